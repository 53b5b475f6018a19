//! The neighbour graph of a layout in compressed sparse rows: element `i` has the neighbours
//! `indices[indptr[i] .. indptr[i + 1]]` (for a grid the four of thesis eq. 6.14).

use crate::error::{ensure, KernelError};

/// A checked view of a neighbour graph of `n` elements.
#[derive(Debug, Clone, Copy)]
pub struct Graph<'a> {
    indptr: &'a [u32],
    indices: &'a [u32],
}

impl<'a> Graph<'a> {
    /// Check and view: `indptr` has `n + 1` non-decreasing entries from 0 to
    /// `indices.len()`; every index is below `n` and differs from its own element.
    pub fn new(indptr: &'a [u32], indices: &'a [u32]) -> Result<Self, KernelError> {
        ensure(
            !indptr.is_empty() && indptr[0] == 0,
            "indptr",
            "must start with 0",
        )?;
        let n = indptr.len() - 1;
        ensure(
            indptr[n] as usize == indices.len(),
            "indices",
            "length must equal indptr[n]",
        )?;
        for i in 0..n {
            let (a, b) = (indptr[i] as usize, indptr[i + 1] as usize);
            ensure(a <= b, "indptr", "must be non-decreasing")?;
            for &j in &indices[a..b] {
                ensure((j as usize) < n, "indices", "index out of range")?;
                ensure(j as usize != i, "indices", "an element lists itself")?;
            }
        }
        Ok(Self { indptr, indices })
    }

    /// View a graph that [`Graph::new`] accepted before, without the pass over its indices
    /// (an inconsistent graph makes [`Graph::of`] panic, never read out of bounds).
    pub fn new_trusted(indptr: &'a [u32], indices: &'a [u32]) -> Self {
        Self { indptr, indices }
    }

    /// Number of elements.
    #[inline]
    pub fn len(&self) -> usize {
        self.indptr.len() - 1
    }

    /// True without elements.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The neighbours of element `i`.
    #[inline]
    pub fn of(&self, i: usize) -> &'a [u32] {
        &self.indices[self.indptr[i] as usize..self.indptr[i + 1] as usize]
    }

    /// Position of element `i`'s first neighbour in the flat list (for values parallel to
    /// the indices, such as weights).
    #[inline]
    pub fn start(&self, i: usize) -> usize {
        self.indptr[i] as usize
    }

    /// Number of (directed) neighbour pairs.
    #[inline]
    pub fn nnz(&self) -> usize {
        self.indices.len()
    }

    /// The most neighbours of any element.
    pub fn max_degree(&self) -> usize {
        self.indptr
            .windows(2)
            .map(|w| (w[1] - w[0]) as usize)
            .max()
            .unwrap_or(0)
    }

    /// The row pointer.
    pub fn indptr(&self) -> &'a [u32] {
        self.indptr
    }

    /// The flat neighbour list.
    pub fn indices(&self) -> &'a [u32] {
        self.indices
    }
}
