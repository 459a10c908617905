//! `radiosity-core`: the device side of the radiosity toolkit.
//!
//! `no_std`, no `alloc`, no `unsafe`, no clock, no `f64`, and no panic on any input.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod codec;
pub mod crc;
pub mod scalar;
pub mod solver;
pub mod table;
pub mod write;

pub use codec::{FfCodec, Frac};
pub use scalar::{Fixed, Scalar};
pub use solver::{Buffers, Config, NoProgressReason, Outcome, Solver, SolverError};
pub use table::{Table, TableError, FORMAT_VERSION, MAGIC};
pub use write::{
    required_len, write_table, GroupSpec, MemberSpec, PatchSpec, RowsSpec, TableSpec, WriteError,
};
