//! The one error type of the core crate. The Python binding maps each variant to its own
//! exception class (`texsense.exceptions`).

use std::fmt;

/// Everything that can go wrong inside a kernel call. Kernels check their inputs at the
/// boundary and then trust them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CoreError {
    /// An array had the wrong length or shape.
    Shape {
        /// Which argument.
        what: &'static str,
        /// What was expected, in words ("800 = 10 frames x 80 elements").
        expected: String,
        /// What was given.
        got: String,
    },
    /// An index (for example a neighbour index) points outside the valid range.
    Index {
        /// Which argument.
        what: &'static str,
        /// The offending index.
        index: usize,
        /// The exclusive upper bound.
        bound: usize,
    },
    /// A parameter value is outside its domain.
    Parameter {
        /// Which parameter.
        what: &'static str,
        /// Why it is invalid.
        why: String,
    },
}

impl fmt::Display for CoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CoreError::Shape {
                what,
                expected,
                got,
            } => write!(f, "{what}: expected {expected}, got {got}"),
            CoreError::Index { what, index, bound } => {
                write!(f, "{what}: index {index} is out of range 0..{bound}")
            }
            CoreError::Parameter { what, why } => write!(f, "{what}: {why}"),
        }
    }
}

impl std::error::Error for CoreError {}

impl From<texsense_kernels::KernelError> for CoreError {
    fn from(e: texsense_kernels::KernelError) -> Self {
        CoreError::Parameter {
            what: e.what,
            why: e.why.into(),
        }
    }
}

/// Check that a slice has the expected length.
pub(crate) fn check_len(what: &'static str, len: usize, expected: usize) -> Result<(), CoreError> {
    if len == expected {
        Ok(())
    } else {
        Err(CoreError::Shape {
            what,
            expected: format!("length {expected}"),
            got: format!("length {len}"),
        })
    }
}

/// Frames in a row-major batch of `len` values of `n` elements each.
pub(crate) fn frames_of(what: &'static str, len: usize, n: usize) -> Result<usize, CoreError> {
    if n == 0 || !len.is_multiple_of(n) {
        return Err(CoreError::Shape {
            what,
            expected: format!("a multiple of {n} elements"),
            got: format!("length {len}"),
        });
    }
    Ok(len / n)
}
