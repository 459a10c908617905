//! The identities a table stores: light-group ids (step 3, core's [`radiosity_core::group_id`]) and the scene
//! fingerprint (step 6), both FNV-1a (Fowler, Noll, Vo; IETF draft draft-eastlake-fnv).

use super::BakeError;
use crate::patch::Patch;

/// The table id of a light group: 32-bit FNV-1a of its name (core owns the hash, so firmware and relight
/// scripts can refer to a group by name).
pub use radiosity_core::group_id;

/// The ids of `names` ([`group_id`]), in order.
///
/// # Errors
/// [`BakeError::GroupIdCollision`] if two names hash to the same id.
pub fn group_ids(names: &[String]) -> Result<Vec<u32>, BakeError> {
    let ids: Vec<u32> = names.iter().map(|s| group_id(s)).collect();
    for a in 0..ids.len() {
        for b in a + 1..ids.len() {
            if ids[a] == ids[b] {
                return Err(BakeError::GroupIdCollision(names[a].clone(), names[b].clone(), ids[a]));
            }
        }
    }
    Ok(ids)
}

/// The scene fingerprint stored in a table's header: 64-bit FNV-1a over the patch count and, per patch in
/// order, its parent face and material index (`u64` LE) and the f64 bits (LE) of its area, centroid and normal.
/// It identifies the scene and its meshing: any moved, resized, re-meshed or re-materialled patch changes it
/// (up to hash collisions, probability about `2^-64` per pair of scenes). Reflectance and emission values are
/// not included: they are in the table itself. `-0.0` is hashed as `0.0`, so the sign of a zero coordinate
/// does not matter.
#[must_use]
pub fn scene_fingerprint(patches: &[Patch]) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h = OFFSET;
    let mut eat = |word: u64| {
        for b in word.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(PRIME);
        }
    };
    let bits = |x: f64| (x + 0.0).to_bits();
    eat(patches.len() as u64);
    for p in patches {
        eat(p.face as u64);
        eat(p.material as u64);
        eat(bits(p.area));
        for v in [p.centroid, p.normal] {
            eat(bits(v.x));
            eat(bits(v.y));
            eat(bits(v.z));
        }
    }
    h
}
