//! The table format (layer 2): the byte layout, [`Table::parse`] (the one checked constructor), read views
//! and the writer. The specification of the bytes is `docs/format.md`, included below; the golden tests in
//! `core/tests/format.rs` pin it.
//!
//! Files: `layout` (header, [`SectionSizes`], little-endian readers), `error` ([`TableError`]), `parse`
//! ([`Table::parse`] and its validation), `view` (accessors and [`Row`]), [`write`](mod@write) (the writer the
//! host calls), `hier` (hierarchical tables: [`HierTable::parse`] and its views) and
//! [`hier_write`](mod@hier_write) (their writer, [`write_hier_table`]). Each uses only the codecs ([`crate::codec`]) and the CRC ([`crate::crc`]) below it.
//!
#![doc = include_str!("../../../docs/format.md")]

mod error;
mod hier;
pub mod hier_write;
mod layout;
mod parse;
mod view;
pub mod write;

pub use error::{IndexArray, OffsetArray, QuantParam, TableError, TreeFault};
pub(crate) use hier::{slot_of, NodeSections};
pub use hier::{HierMember, HierSectionSizes, HierTable};
pub use hier_write::{hier_required_len, write_hier_table, HierSpec, NodeSpec};
pub use layout::{SectionSizes, TransferSection};
pub use parse::Table;
pub(crate) use view::le;
pub use view::{Entries, Member, Row};
pub use write::{
    required_len, write_table, GroupSpec, MemberSpec, PatchSpec, RowsSpec, TableSpec, WriteError,
};

/// The four bytes every table starts with.
pub const MAGIC: [u8; 4] = *b"RFT\x1a";

/// The light-group id a host writes for a group named `name`: the 32-bit FNV-1a hash of the name's UTF-8
/// bytes (Fowler, Noll, Vo; IETF draft draft-eastlake-fnv). The table stores ids, not names; firmware and
/// relight scripts refer to a group by name through this function ([`Table::find_group`]`(group_id(name))`).
/// The format itself does not depend on it: any `u32` is a valid id.
#[must_use]
pub const fn group_id(name: &str) -> u32 {
    let bytes = name.as_bytes();
    let mut h: u32 = 0x811c_9dc5;
    let mut i = 0;
    while i < bytes.len() {
        h ^= bytes[i] as u32;
        h = h.wrapping_mul(0x0100_0193);
        i += 1;
    }
    h
}

/// The format version of flat tables ([`Table`]), which this crate reads and writes. The version names the
/// layout: flat tables keep version 3, hierarchical tables are version [`HIER_FORMAT_VERSION`].
pub const FORMAT_VERSION: u16 = 3;

/// The format version of hierarchical tables ([`HierTable`], `docs/format.md`, "Hierarchical tables").
pub const HIER_FORMAT_VERSION: u16 = 5;

#[cfg(test)]
mod tests {
    use super::group_id;

    #[test]
    fn group_id_is_fnv1a_32() {
        // Test vectors of the FNV reference (draft-eastlake-fnv, appendix C).
        assert_eq!(group_id(""), 0x811c_9dc5);
        assert_eq!(group_id("a"), 0xe40c_292c);
        assert_eq!(group_id("foobar"), 0xbf9c_f968);
        // Evaluable at compile time, as firmware constants need.
        const LIGHT: u32 = group_id("light");
        assert_eq!(LIGHT, group_id(&String::from("light")));
    }
}
