//! The one error of the kernels: what was wrong, in static words (no allocation). The
//! desktop core maps it to its own error; the C ABI to an error code.

use core::fmt;

/// A parameter or array that a kernel cannot run with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KernelError {
    /// Which parameter or array.
    pub what: &'static str,
    /// What is wrong with it.
    pub why: &'static str,
}

impl KernelError {
    pub(crate) const fn new(what: &'static str, why: &'static str) -> Self {
        Self { what, why }
    }
}

impl fmt::Display for KernelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.what, self.why)
    }
}

/// `Err` unless `ok`.
#[inline]
pub(crate) fn ensure(ok: bool, what: &'static str, why: &'static str) -> Result<(), KernelError> {
    if ok {
        Ok(())
    } else {
        Err(KernelError::new(what, why))
    }
}
