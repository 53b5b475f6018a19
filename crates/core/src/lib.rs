//! Pure-Rust kernels of texsense.
//!
//! Nothing in this crate knows about Python: the same kernels can later serve firmware
//! (through a C ABI) or the browser (through WASM). The PyO3 binding lives in
//! `crates/python` and only converts arrays and errors.
//!
//! Modules are named after the concept they implement:
//! - [`topology`]: the 4-neighbour graph of a sensor layout, in compressed sparse rows;
//! - [`convert`]: capacitance -> compression per element (thesis eq. 2.1) through the
//!   material curve;
//! - [`detect`]: failure detection on raw capacitance (§6.5.2.5);
//! - [`repair`]: the local repairs of failed readings: zero, last value, eq. 6.14 neighbour
//!   mean, weighted mean;
//! - [`drift`]: drift as a superposition of step responses, recursive (thesis eq. 5.4/5.8);
//! - [`everett`]: the Everett function on a grid and the Everett terms of a history;
//! - [`preisach`]: the numerical Preisach model (thesis eq. 4.15-4.22), many elements at once;
//! - [`compensation`]: Preisach then drift in one pass;
//! - [`chain`]: detect -> convert -> compensation -> repair, the whole mat in one pass;
//! - [`par`]: the one parallel loop over blocks of elements;
//! - [`lanes`]: the chain's glue between kernels (inputs from codes, repair's first pass) in
//!   SIMD lanes;
//! - [`simd`]: runtime choice between the scalar kernels and their AVX2 paths;
//! - [`spacer`]: the spacer mechanics of the virtual sensor (backbone, friction, creep);
//! - [`bouc_wen`]: a second spacer law of another family (Bouc–Wen friction, Norton creep);
//! - [`text`]: rows of numbers in text files, the readers' fast path;
//! - [`stats`]: one frame's pressure statistics on a grid, the station's per-frame numbers.

pub mod aligned;
pub mod bouc_wen;
pub mod chain;
pub mod compensation;
pub mod convert;
pub mod detect;
pub mod drift;
pub mod error;
pub mod everett;
pub mod lanes;
pub mod live;
pub mod mcu;
pub mod par;
pub mod preisach;
pub mod repair;
pub mod simd;
mod snapshot;
pub mod spacer;
pub mod spacer_batch;
pub mod stats;
pub mod text;
pub mod topology;

pub use bouc_wen::{BoucWenBank, BoucWenParams};
pub use chain::{Chain, Stage as ChainStage};
pub use compensation::Compensation;
pub use convert::{Converter, Curve};
pub use drift::{DriftBank, Kernel};
pub use error::CoreError;
pub use everett::{everett_terms, Everett, EverettTerms};
pub use preisach::PreisachBank;
pub use repair::{LocalRepair, Method as RepairMethod};
pub use spacer::{SpacerBank, SpacerLaw, SpacerParams};
pub use spacer_batch::SpacerBatch;
pub use topology::Neighbours;
