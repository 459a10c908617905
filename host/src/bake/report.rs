//! A bake's own stage report: what each step did (counts, what sparsification dropped, sizes). How good the
//! table is, is [`crate::evaluate`]'s to say.

use std::fmt;

use serde::Serialize;

use super::{EnergyDropped, RuntimeState};
use crate::inspect::SectionBytes;
use crate::rgb::Rgb;
use crate::text::counted;

/// A dynamic light group as written to the table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroupReport {
    /// Group name.
    pub name: String,
    /// Table id ([`super::group_id`]).
    pub id: u32,
    /// Member patches.
    pub members: usize,
    /// Default intensity (RGB).
    pub default_intensity: Rgb,
}

/// What the steps of a bake did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeReport {
    /// Patches.
    pub patches: usize,
    /// Materials.
    pub materials: usize,
    /// Dynamic light groups (step 3).
    pub groups: Vec<GroupReport>,
    /// Light-group members in total.
    pub members: usize,
    /// Sparsification threshold (step 1).
    pub threshold: f64,
    /// Nonzero form factors before sparsification.
    pub nonzeros_before: usize,
    /// Nonzero form factors after sparsification.
    pub nonzeros_after: usize,
    /// Entries stored in the table: the sparsified rows of the patches with run-time state, without their
    /// entries to receivers without state (equal to `nonzeros_after` when every patch has state).
    pub table_entries: usize,
    /// Energy dropped by sparsification.
    pub energy_dropped: EnergyDropped,
    /// Codec name (core's `Display` of `FfCodec`; step 6).
    pub codec: String,
    /// Bits per form-factor code.
    pub ff_bits: u8,
    /// Table bytes per section.
    pub table_bytes: SectionBytes,
    /// Total table bytes per stored entry.
    pub bytes_per_entry: f64,
    /// Whether the static base is solved (always true for a bake; step 2).
    pub base_solved: bool,
    /// Patches with static emission.
    pub static_emitters: usize,
    /// Patches needing run-time state (step 5).
    pub runtime_state: RuntimeState,
    /// The scene fingerprint stored in the table ([`super::scene_fingerprint`]).
    pub fingerprint: u64,
}

impl fmt::Display for BakeReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let e = &self.energy_dropped;
        writeln!(
            f,
            "patches            {} ({})",
            self.patches,
            counted(self.materials, "material", "materials")
        )?;
        writeln!(f, "scene fingerprint  {:#018x}", self.fingerprint)?;
        writeln!(
            f,
            "light groups       {} dynamic, {}",
            self.groups.len(),
            counted(self.members, "member", "members")
        )?;
        for g in &self.groups {
            writeln!(
                f,
                "  {:<16} id {:#010x}  {}  default {:?}",
                g.name,
                g.id,
                counted(g.members, "member", "members"),
                g.default_intensity.to_array()
            )?;
        }
        writeln!(
            f,
            "static emitters    {} (folded into the solved base)",
            counted(self.static_emitters, "patch", "patches")
        )?;
        writeln!(
            f,
            "form factors       {} -> {} nonzeros (threshold {}), {} stored (rows of patches with state)",
            self.nonzeros_before, self.nonzeros_after, self.threshold, self.table_entries
        )?;
        writeln!(
            f,
            "energy dropped     {:.3e} of all power transported (area-weighted, at uniform radiosity); of a \
             patch's outgoing power mean {:.3e}, max {:.3e}; largest share of a row {:.3e}, of a receiver's \
             incoming power {:.3e}",
            e.area_weighted, e.mean_row, e.max_row, e.max_row_fraction, e.max_receiver_fraction
        )?;
        if e.max_entry_scale > 0.0 {
            writeln!(
                f,
                "energy returned    to the kept entries (each changed by at most {:.3e}); rows lose {:.3e} of all \
                 power, receivers' incoming power changes by at most {:.3e}",
                e.max_entry_scale, e.net_area_weighted, e.max_incoming_change
            )?;
        } else {
            writeln!(f, "energy returned    none; rows lose {:.3e} of all power", e.net_area_weighted)?;
        }
        writeln!(f, "codec              {} ({} bits)", self.codec, self.ff_bits)?;
        writeln!(
            f,
            "table bytes        {} ({:.2} bytes per entry)",
            self.table_bytes.total, self.bytes_per_entry
        )?;
        writeln!(f, "{}", self.table_bytes)?;
        write!(
            f,
            "runtime state      {} of {} (reachable by a dynamic light; the others show the static base; {} to \
             black stateless receivers dropped)",
            self.runtime_state.reachable,
            counted(self.runtime_state.patches, "patch", "patches"),
            counted(self.runtime_state.entries_to_stateless, "entry", "entries")
        )
    }
}
