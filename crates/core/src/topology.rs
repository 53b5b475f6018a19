//! The neighbour graph of a sensor layout in compressed sparse rows (CSR).
//!
//! Element `i` has the neighbours `indices[indptr[i]..indptr[i + 1]]`. For a grid these are
//! the up to four elements left, right, above and below that exist (thesis eq. 6.14 uses
//! exactly these four).

use texsense_kernels::graph::Graph;

use crate::error::CoreError;

/// Neighbour lists of `n` elements (the kernels' [`Graph`] owned).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Neighbours {
    indptr: Vec<u32>,
    indices: Vec<u32>,
}

impl Neighbours {
    /// Build and validate a CSR neighbour graph.
    ///
    /// `indptr` must have `n + 1` non-decreasing entries starting at 0 and ending at
    /// `indices.len()` (below 2^32); every index must be `< n` and differ from its own
    /// element.
    pub fn new(indptr: Vec<usize>, indices: Vec<u32>) -> Result<Self, CoreError> {
        if indptr.is_empty() || indptr[0] != 0 {
            return Err(CoreError::Parameter {
                what: "indptr",
                why: "must start with 0 and have n + 1 entries".into(),
            });
        }
        let n = indptr.len() - 1;
        if *indptr.last().unwrap_or(&0) != indices.len() {
            return Err(CoreError::Shape {
                what: "indices",
                expected: format!("length {} (= indptr[n])", indptr[n]),
                got: format!("length {}", indices.len()),
            });
        }
        for i in 0..n {
            if indptr[i + 1] < indptr[i] {
                return Err(CoreError::Parameter {
                    what: "indptr",
                    why: format!(
                        "must be non-decreasing, but indptr[{}] < indptr[{i}]",
                        i + 1
                    ),
                });
            }
            for &j in &indices[indptr[i]..indptr[i + 1]] {
                let j = j as usize;
                if j >= n {
                    return Err(CoreError::Index {
                        what: "indices",
                        index: j,
                        bound: n,
                    });
                }
                if j == i {
                    return Err(CoreError::Parameter {
                        what: "indices",
                        why: format!("element {i} lists itself as its neighbour"),
                    });
                }
            }
        }
        if indices.len() > u32::MAX as usize {
            return Err(CoreError::Parameter {
                what: "indices",
                why: "more than 2^32 neighbour pairs".into(),
            });
        }
        let indptr = indptr.into_iter().map(|v| v as u32).collect();
        Ok(Self { indptr, indices })
    }

    /// A graph of `n` elements without any neighbours.
    pub fn empty(n: usize) -> Self {
        Self {
            indptr: vec![0; n + 1],
            indices: Vec::new(),
        }
    }

    /// The 4-neighbour graph of a full `rows x cols` grid, elements numbered row-major.
    pub fn grid4(rows: usize, cols: usize) -> Self {
        let mut indptr: Vec<u32> = Vec::with_capacity(rows * cols + 1);
        let mut indices = Vec::with_capacity(rows * cols * 4);
        indptr.push(0);
        for r in 0..rows {
            for c in 0..cols {
                if c > 0 {
                    indices.push((r * cols + c - 1) as u32);
                }
                if c + 1 < cols {
                    indices.push((r * cols + c + 1) as u32);
                }
                if r > 0 {
                    indices.push(((r - 1) * cols + c) as u32);
                }
                if r + 1 < rows {
                    indices.push(((r + 1) * cols + c) as u32);
                }
                indptr.push(indices.len() as u32);
            }
        }
        Self { indptr, indices }
    }

    /// Number of elements.
    #[inline]
    pub fn len(&self) -> usize {
        self.indptr.len() - 1
    }

    /// True when the graph has no elements.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The neighbours of element `i`.
    #[inline]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.indices[self.indptr[i] as usize..self.indptr[i + 1] as usize]
    }

    /// Position of element `i`'s first neighbour in the flat list (for values stored
    /// parallel to the indices, such as weights).
    #[inline]
    pub fn start(&self, i: usize) -> usize {
        self.indptr[i] as usize
    }

    /// Number of (directed) neighbour pairs.
    #[inline]
    pub fn nnz(&self) -> usize {
        self.indices.len()
    }

    /// The kernels' view of the graph (checked when it was built).
    #[inline]
    pub fn graph(&self) -> Graph<'_> {
        Graph::new_trusted(&self.indptr, &self.indices)
    }

    /// The row pointer.
    pub fn indptr(&self) -> &[u32] {
        &self.indptr
    }

    /// The flat neighbour list.
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid4_corner_edge_and_centre() {
        let g = Neighbours::grid4(3, 3);
        assert_eq!(g.len(), 9);
        assert_eq!(g.of(0), &[1, 3]);
        assert_eq!(g.of(1), &[0, 2, 4]);
        assert_eq!(g.of(4), &[3, 5, 1, 7]);
        assert_eq!(g.of(8), &[7, 5]);
    }

    #[test]
    fn rejects_out_of_range_and_self_loops() {
        assert!(matches!(
            Neighbours::new(vec![0, 1], vec![3]),
            Err(CoreError::Index { index: 3, .. })
        ));
        assert!(matches!(
            Neighbours::new(vec![0, 1], vec![0]),
            Err(CoreError::Parameter { .. })
        ));
        assert!(matches!(
            Neighbours::new(vec![0, 2], vec![0]),
            Err(CoreError::Shape { .. })
        ));
        assert!(Neighbours::new(vec![], vec![]).is_err());
    }
}
