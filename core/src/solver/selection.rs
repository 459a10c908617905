//! Which slot shoots next: the winner (largest unshot magnitude, ties to the lower slot) of each block of
//! consecutive slots, kept in [`Buffers::selection`](super::Buffers::selection), and the scan over the block
//! winners (crate docs, "Cost model").

use super::{get3, magnitude, SelectionState, Solver};
use crate::scalar::Scalar;

impl<S: Scalar> Solver<'_, S> {
    pub(super) fn key(&self, i: u32) -> S {
        magnitude(get3(self.buf.unshot, i))
    }

    /// Selection rank of slot `i` ([`Scalar::rank`] of its unshot magnitude): an unusable magnitude (not
    /// finite for f32, saturated for fixed point) ranks above every usable one, so an overflow is selected and
    /// reported; otherwise the larger magnitude, ties to the lower slot.
    pub(super) fn rank(&self, i: u32) -> S::Rank {
        self.key(i).rank(i)
    }

    /// Slots of block `b`.
    pub(super) fn block_range(&self, b: u32) -> core::ops::Range<u32> {
        let start = b << self.block_shift;
        start.min(self.slots)..start.saturating_add(1 << self.block_shift).min(self.slots)
    }

    /// Scans block `b` for its winner and stores it; returns slots scanned (work units).
    pub(super) fn rescan_block(&mut self, b: u32) -> u32 {
        let range = self.block_range(b);
        let len = range.end - range.start;
        let mut best = range.start;
        let mut best_rank = self.rank(best);
        for i in range.start + 1..range.end {
            let r = self.rank(i);
            if r > best_rank {
                best = i;
                best_rank = r;
            }
        }
        self.set_winner(b, best);
        len
    }

    /// Whether block `b`'s stored winner is current (its block is rebuilt).
    pub(super) fn block_valid(&self, b: u32) -> bool {
        match self.selection {
            SelectionState::Valid => true,
            SelectionState::Rebuilding(next) => b < next,
        }
    }

    /// Records that `slot`'s unshot power changed (in any direction). The comparison with its block's winner
    /// is part of the change's own unit; returns the extra work units: the block's length when `slot` was the
    /// winner (it may have shrunk) and the block is rescanned, else 0.
    pub(super) fn update_leaf(&mut self, slot: u32) -> u32 {
        self.selected = None;
        let b = slot >> self.block_shift;
        if !self.block_valid(b) {
            return 0;
        }
        let w = self.buf.selection.get(b as usize).copied().unwrap_or(slot);
        if w == slot {
            self.rescan_block(b)
        } else {
            if self.rank(slot) > self.rank(w) {
                self.set_winner(b, slot);
            }
            0
        }
    }

    /// The slot with the largest unshot magnitude (ties to the lower slot), from the block winners; returns it
    /// and the blocks scanned (work units).
    pub(super) fn select(&self) -> (u32, u32) {
        let mut best = self.buf.selection.first().copied().unwrap_or(0);
        let mut best_rank = self.rank(best);
        for b in 1..self.blocks {
            let w = self.buf.selection.get(b as usize).copied().unwrap_or(0);
            let r = self.rank(w);
            if r > best_rank {
                best = w;
                best_rank = r;
            }
        }
        (best, self.blocks)
    }
}
