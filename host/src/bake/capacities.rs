//! What a firmware build needs to know of one table.

use radiosity_core::{BufferSizes, Table};
use serde::Serialize;

use crate::inspect::TableCounts;

/// What a firmware build needs to know of one table: its counts, the solver's buffer sizes (core's
/// [`BufferSizes::of`], the one place they are derived) and the transfer relight's needs.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Capacities {
    /// The table's counts (patches, patches with state, materials, groups, members, entries, index and code
    /// widths, transfer basis).
    #[serde(flatten)]
    pub counts: TableCounts,
    /// Longest row (entries).
    pub max_row_len: usize,
    /// Elements of each solver buffer (and of the Jacobi scratch buffer: `slots`).
    pub buffers: BufferSizes,
    /// Bytes of RAM the solver's buffers take with f32 (`BufferSizes::bytes`).
    pub buffer_bytes_f32: usize,
    /// Bytes of RAM the solver's buffers take with fixed point.
    pub buffer_bytes_fixed: usize,
    /// Output elements (`[S; 3]`) of [`radiosity_core::relight_transfer`]: patches with a transfer basis, else 0.
    pub transfer_out: usize,
    /// Work units of one [`radiosity_core::relight_transfer`] ([`radiosity_core::transfer_cost`]); 0 without a
    /// transfer basis.
    pub transfer_cost: usize,
    /// Table size in bytes.
    pub table_bytes: usize,
}

impl Capacities {
    /// The capacities of a parsed table.
    #[must_use]
    pub fn of_table(table: &Table<'_>, table_bytes: usize) -> Capacities {
        let counts = TableCounts::of(table);
        let max_row_len = (0..table.state_count())
            .filter_map(|i| table.row(i))
            .map(|r| (r.end - r.start) as usize)
            .max()
            .unwrap_or(0);
        let buffers = BufferSizes::of(table);
        Capacities {
            counts,
            max_row_len,
            buffers,
            buffer_bytes_f32: buffers.bytes::<f32>(),
            buffer_bytes_fixed: buffers.bytes::<radiosity_core::Fixed>(),
            transfer_out: if counts.transfer { counts.patches } else { 0 },
            transfer_cost: if counts.transfer { radiosity_core::transfer_cost(table) as usize } else { 0 },
            table_bytes,
        }
    }
}
