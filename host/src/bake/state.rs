//! Step 5 of a bake: which patches need run-time state, and their rows over slots (see the [`crate::bake`]
//! docs).

use std::collections::VecDeque;

use serde::Serialize;

use crate::patch::FormFactorMatrix;
use crate::rgb::Rgb;

/// Patches needing run-time state (see the [`crate::bake`] docs, step 5), breadth-first over the stored rows.
#[must_use]
pub fn reachable_patches(sparse: &FormFactorMatrix, group: &[Option<usize>], rho: &[Rgb]) -> Vec<bool> {
    let mut reached = vec![false; sparse.n()];
    let mut queue = VecDeque::new();
    for (i, g) in group.iter().enumerate() {
        if g.is_some() {
            reached[i] = true;
            queue.push_back(i);
        }
    }
    while let Some(i) = queue.pop_front() {
        for (j, f) in sparse.row(i) {
            if f > 0.0 && !reached[j] && rho[j].cmpgt(Rgb::ZERO).any() {
                reached[j] = true;
                queue.push_back(j);
            }
        }
    }
    reached
}

/// How many patches carry run-time state on the device (see the [`crate::bake`] docs, step 5).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RuntimeState {
    /// Patches a dynamic light can reach (including the members): the table's state count.
    pub reachable: usize,
    /// Patches in the table.
    pub patches: usize,
    /// Entries dropped from the rows of patches with state because their receiver has none (a receiver black
    /// in every channel: no effect on any radiosity at the baked reflectances).
    pub entries_to_stateless: usize,
}

/// The rows of the patches with run-time state, as core's writer takes them: shooter and receiver indices are
/// slots (positions in `patch`).
pub(super) struct SlotRows {
    /// Patch of each slot, ascending.
    pub(super) patch: Vec<u32>,
    pub(super) row_start: Vec<u32>,
    pub(super) receiver: Vec<u32>,
    pub(super) value: Vec<f64>,
    /// Entries of rows with state whose receiver has none (dropped).
    pub(super) dropped: usize,
}

impl SlotRows {
    pub(super) fn new(ff: &FormFactorMatrix, state: &[bool]) -> SlotRows {
        let mut slot_of = vec![None; ff.n()];
        let mut patch = Vec::new();
        for (i, _) in state.iter().enumerate().filter(|(_, &s)| s) {
            slot_of[i] = Some(patch.len() as u32);
            patch.push(i as u32);
        }
        let mut rows =
            SlotRows { patch, row_start: vec![0], receiver: Vec::new(), value: Vec::new(), dropped: 0 };
        for &i in &rows.patch {
            for (j, f) in ff.row(i as usize) {
                match slot_of[j] {
                    Some(r) => {
                        rows.receiver.push(r);
                        rows.value.push(f);
                    }
                    None => rows.dropped += 1,
                }
            }
            rows.row_start.push(rows.receiver.len() as u32);
        }
        rows
    }

    /// What the rows say of the run-time state of `patches` patches.
    pub(super) fn runtime_state(&self, patches: usize) -> RuntimeState {
        RuntimeState { reachable: self.patch.len(), patches, entries_to_stateless: self.dropped }
    }
}
