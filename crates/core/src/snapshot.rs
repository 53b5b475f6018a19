//! Snapshots of a compiled chain's state: every per-element state as bytes (little-endian),
//! versioned, so that a stream continues in another process exactly where it stopped
//! ([`crate::chain::Chain::snapshot`]).

use crate::error::CoreError;

/// Appends little-endian values.
#[derive(Debug, Default)]
pub(crate) struct Writer {
    pub(crate) buf: Vec<u8>,
}

impl Writer {
    pub(crate) fn u32(&mut self, v: u32) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn u64(&mut self, v: u64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f64(&mut self, v: f64) {
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f64s(&mut self, v: &[f64]) {
        for &x in v {
            self.f64(x);
        }
    }
}

/// Reads what a [`Writer`] wrote; running out of bytes is an error, never a panic.
#[derive(Debug)]
pub(crate) struct Reader<'a> {
    buf: &'a [u8],
}

impl<'a> Reader<'a> {
    pub(crate) fn new(buf: &'a [u8]) -> Self {
        Self { buf }
    }

    pub(crate) fn error(&self, why: &str) -> CoreError {
        CoreError::Parameter {
            what: "snapshot",
            why: why.into(),
        }
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], CoreError> {
        if self.buf.len() < N {
            return Err(self.error("cut short"));
        }
        let (a, b) = self.buf.split_at(N);
        self.buf = b;
        let mut out = [0; N];
        out.copy_from_slice(a);
        Ok(out)
    }

    pub(crate) fn u32(&mut self) -> Result<u32, CoreError> {
        Ok(u32::from_le_bytes(self.take()?))
    }

    pub(crate) fn u64(&mut self) -> Result<u64, CoreError> {
        Ok(u64::from_le_bytes(self.take()?))
    }

    pub(crate) fn f64(&mut self) -> Result<f64, CoreError> {
        Ok(f64::from_le_bytes(self.take()?))
    }

    pub(crate) fn f64s(&mut self, out: &mut [f64]) -> Result<(), CoreError> {
        for x in out {
            *x = self.f64()?;
        }
        Ok(())
    }

    /// A count that must equal what this chain has (`what`, for the message).
    pub(crate) fn expect(&mut self, what: &str, want: usize) -> Result<(), CoreError> {
        let got = self.u32()? as usize;
        if got != want {
            return Err(CoreError::Parameter {
                what: "snapshot",
                why: format!("{what}: the snapshot has {got}, this chain {want}"),
            });
        }
        Ok(())
    }

    pub(crate) fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }
}
