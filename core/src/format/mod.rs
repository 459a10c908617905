//! The table format (layer 2): the byte layout, [`Table::parse`] (the one checked constructor), read views
//! and the writer. The specification of the bytes is `docs/format.md`, included below; the golden tests in
//! `core/tests/format.rs` pin it.
//!
//! Files: `layout` (header, [`SectionSizes`], little-endian readers), `error` ([`TableError`]), `parse`
//! ([`Table::parse`] and its validation), `view` (accessors and [`Row`]), [`write`](mod@write) (the writer the
//! host calls). Each uses only the codecs ([`crate::codec`]) and the CRC ([`crate::crc`]) below it.
//!
#![doc = include_str!("../../../docs/format.md")]

mod error;
mod layout;
mod parse;
mod view;
pub mod write;

pub use error::{IndexArray, OffsetArray, QuantParam, TableError};
pub use layout::SectionSizes;
pub use parse::Table;
pub use view::{Entries, Member, Row};
pub use write::{
    required_len, write_table, GroupSpec, MemberSpec, PatchSpec, RowsSpec, TableSpec, WriteError,
};

/// The four bytes every table starts with.
pub const MAGIC: [u8; 4] = *b"RFT\x1a";

/// The format version this crate reads and writes.
pub const FORMAT_VERSION: u16 = 3;
