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

/// Whether a table and the device solver's buffers fit a board ([`firmware_sim::qemu::Board`]): the table in
/// flash, the f32 buffers in RAM. The firmware's own code, statics and stack come on top of both.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct DeviceFit {
    /// The board.
    pub board: &'static str,
    /// Table bytes.
    pub table_bytes: usize,
    /// The board's flash in bytes.
    pub flash: u64,
    /// Bytes of the solver's buffers with f32.
    pub buffer_bytes: usize,
    /// The board's RAM in bytes.
    pub ram: u64,
    /// Table within the flash and buffers within the RAM.
    pub fits: bool,
}

impl DeviceFit {
    /// How the table of `capacities` fits `board`.
    #[must_use]
    pub fn of(capacities: &Capacities, board: &firmware_sim::qemu::Board) -> DeviceFit {
        let (table, buffers) = (capacities.table_bytes, capacities.buffer_bytes_f32);
        DeviceFit {
            board: board.name,
            table_bytes: table,
            flash: board.flash,
            buffer_bytes: buffers,
            ram: board.ram,
            fits: table as u64 <= board.flash && buffers as u64 <= board.ram,
        }
    }
}

impl std::fmt::Display for DeviceFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let share = |a: usize, b: u64| 100.0 * a as f64 / b as f64;
        write!(
            f,
            "{}: table {} of {} bytes of flash ({:.0}%), f32 solver buffers {} of {} bytes of RAM ({:.0}%): {}",
            self.board,
            self.table_bytes,
            self.flash,
            share(self.table_bytes, self.flash),
            self.buffer_bytes,
            self.ram,
            share(self.buffer_bytes, self.ram),
            if self.fits {
                "fits (the firmware's code, statics and stack come on top)"
            } else {
                "does NOT fit (fewer patches: --max-patches; or 8-bit codes: --bits 8)"
            }
        )
    }
}

/// Bytes a table of `patches` patches (all with run-time state) and `ff_bits`-bit codes takes at most: every
/// pair of patches stored (a dense matrix), plus the per-patch sections and the header (core's
/// `SectionSizes`); materials and light groups, a few bytes each, are left out. Sparsification and occlusion
/// usually store far fewer entries, so the bake's table is smaller: this bound is what a budget can promise
/// before any form factor is known.
#[must_use]
pub fn table_bytes_bound(patches: usize, ff_bits: u32) -> u64 {
    let n = patches as u64;
    let index = if n <= 0x1_0000 { 2 } else { 4 };
    // Area f32, material u16, static emission and irradiance 3 x u16 each, row start u32, row exponent u8.
    let per_patch = 4 + 2 + 6 + 6 + 4 + 1;
    let header_and_crc = 64 + 4 + 4;
    header_and_crc + per_patch * n + n * n.saturating_sub(1) * (index + u64::from(ff_bits / 8))
}

/// The most patches whose [`table_bytes_bound`] fits `bytes`.
#[must_use]
pub fn patches_within(bytes: u64, ff_bits: u32) -> usize {
    let (mut lo, mut hi) = (0usize, 1usize << 20);
    while lo < hi {
        let mid = (lo + hi).div_ceil(2);
        if table_bytes_bound(mid, ff_bits) <= bytes {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    lo
}
