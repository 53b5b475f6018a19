//! Arrays that start on a cache line (64 bytes), for the states the SIMD rows read and write
//! a register (64 bytes) at a time: a `Vec` of `f64` or of 24- or 32-byte elements starts
//! where the allocator puts it (16 bytes past a line, say), and then every register's load
//! and store of a group straddles two lines (issue 34, fifteenth round).

use std::alloc::{alloc, dealloc, handle_alloc_error, Layout};
use std::fmt;
use std::ops::{Deref, DerefMut};
use std::ptr::NonNull;

/// A cache line in bytes.
pub const LINE: usize = 64;

/// A fixed-length array of `T` that starts on a cache line: a `Box<[T]>` in all but the
/// alignment of its start.
pub struct Lines<T: Copy> {
    ptr: NonNull<T>,
    len: usize,
}

// SAFETY: `Lines` owns its elements as a `Box<[T]>` does
unsafe impl<T: Copy + Send> Send for Lines<T> {}
// SAFETY: as above (shared references give shared access only)
unsafe impl<T: Copy + Sync> Sync for Lines<T> {}

impl<T: Copy> Lines<T> {
    /// `len` copies of `value`.
    pub fn new(value: T, len: usize) -> Self {
        Self::from_fn(len, |_| value)
    }

    /// A copy of `values`.
    pub fn from_slice(values: &[T]) -> Self {
        Self::from_fn(values.len(), |i| values[i])
    }

    /// `len` values, value `i` made by `f(i)`.
    fn from_fn(len: usize, f: impl Fn(usize) -> T) -> Self {
        let layout = Self::layout(len);
        let ptr = if layout.size() == 0 {
            NonNull::<T>::dangling()
        } else {
            // SAFETY: the layout has a size above zero
            let raw = unsafe { alloc(layout) }.cast::<T>();
            let Some(ptr) = NonNull::new(raw) else {
                handle_alloc_error(layout)
            };
            for i in 0..len {
                // SAFETY: i < len: inside the allocation of `len` values
                unsafe { ptr.as_ptr().add(i).write(f(i)) };
            }
            ptr
        };
        Self { ptr, len }
    }

    fn layout(len: usize) -> Layout {
        let size = std::mem::size_of::<T>()
            .checked_mul(len)
            .expect("an array that fits the address space");
        Layout::from_size_align(size, LINE.max(std::mem::align_of::<T>()))
            .expect("a size within isize")
    }
}

impl<T: Copy> Drop for Lines<T> {
    fn drop(&mut self) {
        let layout = Self::layout(self.len);
        if layout.size() != 0 {
            // SAFETY: allocated in `new` with this layout; `T: Copy` has no drop
            unsafe { dealloc(self.ptr.as_ptr().cast(), layout) };
        }
    }
}

impl<T: Copy> Deref for Lines<T> {
    type Target = [T];

    fn deref(&self) -> &[T] {
        // SAFETY: `len` values written in `new`, owned by `self`
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> DerefMut for Lines<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        // SAFETY: as in `deref`, borrowed mutably through `self`
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.len) }
    }
}

impl<T: Copy> Clone for Lines<T> {
    fn clone(&self) -> Self {
        Self::from_slice(self)
    }
}

/// Empty (what `std::mem::take` leaves).
impl<T: Copy> Default for Lines<T> {
    fn default() -> Self {
        Self::from_fn(0, |_| unreachable!("no values"))
    }
}

impl<T: Copy + fmt::Debug> fmt::Debug for Lines<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<T: Copy + PartialEq> PartialEq for Lines<T> {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl<'a, T: Copy> IntoIterator for &'a Lines<T> {
    type Item = &'a T;
    type IntoIter = std::slice::Iter<'a, T>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<'a, T: Copy> IntoIterator for &'a mut Lines<T> {
    type Item = &'a mut T;
    type IntoIter = std::slice::IterMut<'a, T>;

    fn into_iter(self) -> Self::IntoIter {
        self.iter_mut()
    }
}

/// A row of a block's values on the stack, starting on a cache line.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
pub struct Row<T: Copy, const N: usize>(pub [T; N]);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_start_on_a_line_and_hold_their_values() {
        for len in [1, 7, 8, 100, 1000] {
            let mut a = Lines::new(1.5f64, len);
            assert_eq!(a.as_ptr() as usize % LINE, 0, "len {len}");
            assert!(a.iter().all(|&v| v == 1.5));
            a.iter_mut().enumerate().for_each(|(i, v)| *v = i as f64);
            let b = a.clone();
            assert_eq!(b.as_ptr() as usize % LINE, 0);
            assert_eq!(a, b);
            assert_eq!(b.len(), len);
        }
        let empty: Lines<f64> = Lines::default();
        assert!(empty.is_empty() && Lines::<f64>::from_slice(&[]).is_empty());
        assert_eq!(empty.clone().len(), 0);
        let r = Row([0u8; 3]);
        assert_eq!(&r as *const _ as usize % LINE, 0);
    }
}
