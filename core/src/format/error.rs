//! What can be wrong with a table blob: [`TableError`] and the names of the arrays and parameters it points at.

use core::fmt;

use super::MAGIC;

/// What is wrong with a table blob. Every variant names the place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum TableError {
    /// The blob does not start with [`MAGIC`].
    BadMagic {
        /// The first four bytes found (zero-padded if shorter).
        found: [u8; 4],
    },
    /// The blob is in a format version this crate does not read.
    UnsupportedVersion {
        /// Version in the blob.
        found: u16,
        /// Version this crate reads ([`FORMAT_VERSION`](super::FORMAT_VERSION)).
        expected: u16,
    },
    /// The postcard header could not be decoded.
    BadHeader,
    /// The blob ends inside the header.
    TruncatedHeader,
    /// The blob is shorter than its header says.
    Truncated {
        /// Bytes the header implies.
        expected: usize,
        /// Bytes present.
        actual: usize,
    },
    /// The blob has bytes after the CRC.
    TrailingBytes {
        /// Bytes the header implies.
        expected: usize,
        /// Bytes present.
        actual: usize,
    },
    /// Counts whose sections do not fit in memory (arithmetic overflow) or exceed the index width.
    CountsTooLarge,
    /// Quantization parameters out of range.
    BadQuantParams {
        /// Which parameter.
        param: QuantParam,
        /// Its value.
        value: u32,
    },
    /// The CRC-32 over header and payload does not match the stored one.
    CrcMismatch {
        /// CRC stored in the blob.
        stored: u32,
        /// CRC computed over the bytes.
        computed: u32,
    },
    /// An offset array (row starts or group member starts) does not start at 0, decreases or does not end at
    /// the entry count.
    NonMonotoneOffsets {
        /// Which array.
        array: OffsetArray,
        /// Position in the array of the first bad offset.
        position: u32,
    },
    /// An index (patch, material) is out of range.
    IndexOutOfRange {
        /// Which index array.
        array: IndexArray,
        /// Position in the array.
        position: u32,
        /// The index found.
        index: u32,
        /// The exclusive upper bound.
        bound: u32,
    },
    /// A row's receivers are not strictly increasing.
    UnsortedRow {
        /// The row (shooter patch).
        row: u32,
    },
    /// A row's decoded form factors sum to more than 1.
    RowSumExceedsOne {
        /// The row (shooter patch).
        row: u32,
    },
    /// A patch area is not finite and positive.
    BadArea {
        /// The patch.
        patch: u32,
    },
    /// A light group's default intensity is not finite.
    BadIntensity {
        /// The light group.
        group: u32,
    },
    /// The table has a transfer basis but its static base is not solved: the basis relights as
    /// `B = B_static + sum_g I_g T_g` and needs `B_static` (see the crate docs, "Transfer basis").
    TransferWithoutSolvedBase,
    /// The state count exceeds the patch count.
    StateCountExceedsPatches {
        /// Patches with run-time state in the header.
        state_count: u32,
        /// Patches in the header.
        patch_count: u32,
    },
    /// Some patches have no run-time state but the static base is not solved: a patch without state shows its
    /// static base, which must then be the static solution (see the crate docs, "Run-time state").
    StateWithoutSolvedBase,
    /// The state map (slot -> patch) is not strictly increasing.
    UnsortedStateMap {
        /// The first slot whose patch is not above the previous slot's.
        slot: u32,
    },
    /// A slot's material differs from the material of its patch.
    StateMaterialMismatch {
        /// The slot.
        slot: u32,
    },
    /// A light-group member is a patch without run-time state (a dynamic emitter always has state).
    MemberWithoutState {
        /// Position in the member array.
        position: u32,
        /// The member's patch.
        patch: u32,
    },
    /// [`Table::parse`](super::Table::parse) was given a hierarchical table (format version
    /// [`HIER_FORMAT_VERSION`](super::HIER_FORMAT_VERSION)): read it with [`HierTable::parse`](super::HierTable::parse).
    HierarchicalTable,
    /// [`HierTable::parse`](super::HierTable::parse) was given a flat table (format version
    /// [`FORMAT_VERSION`](super::FORMAT_VERSION)): read it with [`Table::parse`](super::Table::parse).
    FlatTable,
    /// A hierarchical table's node tree is malformed (format docs, "Hierarchical tables").
    BadTree {
        /// The first node found at fault.
        node: u32,
        /// What is wrong there.
        fault: TreeFault,
    },
    /// A node's area differs from the sum of its children's areas by more than f32 rounding allows.
    NodeAreaMismatch {
        /// The node.
        node: u32,
    },
    /// The decoded run sums along a leaf's chain (the leaf and all its ancestors) exceed 1: the power the leaf
    /// reflects would be shot more than once (format docs, "Hierarchical tables", the convergence bound).
    ChainSumExceedsOne {
        /// The leaf (its index among the leaves).
        leaf: u32,
    },
    /// A hierarchical table's light-group member emission (f32) is negative, not finite or above
    /// [`EMISSION_MAX`](crate::codec::EMISSION_MAX).
    BadMemberEmission {
        /// Position in the member array.
        member: u32,
    },
}

/// What is wrong with a hierarchical table's node tree ([`TableError::BadTree`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TreeFault {
    /// The subtree end is not in `node + 1..=node_count`, or a child's subtree reaches past its parent's.
    SubtreeEnd,
    /// The stored parent is not the node whose child list (or the root list) holds the node.
    Parent,
    /// A node's leaf start is not the number of leaves before it in node order.
    LeafStart,
    /// The leaf-node map does not list the leaf nodes in node order, or the leaf count differs from the header.
    LeafNode,
    /// A leaf's stored parent inner index is not its parent's inner index (the inner count for a root leaf).
    LeafParent,
    /// The inner-node map does not list the inner nodes in node order.
    InnerNode,
}

/// The quantization parameter a [`TableError::BadQuantParams`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QuantParam {
    /// Form-factor code width (8 or 16).
    FfBits,
    /// Form-factor exponent bits (0..=4, below the code width).
    FfExponentBits,
    /// Index width in bytes (2 or 4).
    IndexBytes,
    /// A row exponent (0..=64); the value is the row.
    RowExponent,
    /// A transfer-basis step exponent (see [`crate::transfer`]); the value is the light group.
    TransferExponent,
}

/// The offset array a [`TableError::NonMonotoneOffsets`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OffsetArray {
    /// Form-factor row starts.
    RowStart,
    /// Light-group member starts.
    GroupStart,
}

/// The index array a [`TableError::IndexOutOfRange`] refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum IndexArray {
    /// Patch materials.
    PatchMaterial,
    /// Light-group member patches.
    MemberPatch,
    /// Form-factor receivers (slots, bound: the state count).
    EntryReceiver,
    /// The state map: patch of each slot.
    StatePatch,
    /// Hierarchical tables: link receivers (nodes, bound: the node count).
    LinkReceiver,
}

impl TableError {
    /// Every variant's name, in declaration order: what [`TableError::kind`] returns.
    pub const KINDS: [&'static str; 27] = [
        "BadMagic",
        "UnsupportedVersion",
        "BadHeader",
        "TruncatedHeader",
        "Truncated",
        "TrailingBytes",
        "CountsTooLarge",
        "BadQuantParams",
        "CrcMismatch",
        "NonMonotoneOffsets",
        "IndexOutOfRange",
        "UnsortedRow",
        "RowSumExceedsOne",
        "BadArea",
        "BadIntensity",
        "TransferWithoutSolvedBase",
        "StateCountExceedsPatches",
        "StateWithoutSolvedBase",
        "UnsortedStateMap",
        "StateMaterialMismatch",
        "MemberWithoutState",
        "HierarchicalTable",
        "FlatTable",
        "BadTree",
        "NodeAreaMismatch",
        "ChainSumExceedsOne",
        "BadMemberEmission",
    ];

    /// The variant's name without its fields (`"CrcMismatch"`), e.g. for counting which checks a corpus reaches.
    #[must_use]
    pub const fn kind(&self) -> &'static str {
        match self {
            TableError::BadMagic { .. } => "BadMagic",
            TableError::UnsupportedVersion { .. } => "UnsupportedVersion",
            TableError::BadHeader => "BadHeader",
            TableError::TruncatedHeader => "TruncatedHeader",
            TableError::Truncated { .. } => "Truncated",
            TableError::TrailingBytes { .. } => "TrailingBytes",
            TableError::CountsTooLarge => "CountsTooLarge",
            TableError::BadQuantParams { .. } => "BadQuantParams",
            TableError::CrcMismatch { .. } => "CrcMismatch",
            TableError::NonMonotoneOffsets { .. } => "NonMonotoneOffsets",
            TableError::IndexOutOfRange { .. } => "IndexOutOfRange",
            TableError::UnsortedRow { .. } => "UnsortedRow",
            TableError::RowSumExceedsOne { .. } => "RowSumExceedsOne",
            TableError::BadArea { .. } => "BadArea",
            TableError::BadIntensity { .. } => "BadIntensity",
            TableError::TransferWithoutSolvedBase => "TransferWithoutSolvedBase",
            TableError::StateCountExceedsPatches { .. } => "StateCountExceedsPatches",
            TableError::StateWithoutSolvedBase => "StateWithoutSolvedBase",
            TableError::UnsortedStateMap { .. } => "UnsortedStateMap",
            TableError::StateMaterialMismatch { .. } => "StateMaterialMismatch",
            TableError::MemberWithoutState { .. } => "MemberWithoutState",
            TableError::HierarchicalTable => "HierarchicalTable",
            TableError::FlatTable => "FlatTable",
            TableError::BadTree { .. } => "BadTree",
            TableError::NodeAreaMismatch { .. } => "NodeAreaMismatch",
            TableError::ChainSumExceedsOne { .. } => "ChainSumExceedsOne",
            TableError::BadMemberEmission { .. } => "BadMemberEmission",
        }
    }
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            TableError::BadMagic { found } => {
                write!(f, "not a radiosity table: magic {found:02x?}, expected {MAGIC:02x?}")
            }
            TableError::UnsupportedVersion { found, expected } => {
                write!(f, "unsupported table format version {found}, expected {expected}")
            }
            TableError::BadHeader => write!(f, "table header cannot be decoded"),
            TableError::TruncatedHeader => write!(f, "table truncated inside its header"),
            TableError::Truncated { expected, actual } => {
                write!(f, "table truncated: {actual} bytes, header implies {expected}")
            }
            TableError::TrailingBytes { expected, actual } => {
                write!(f, "table has trailing bytes: {actual} bytes, header implies {expected}")
            }
            TableError::CountsTooLarge => {
                write!(f, "table counts too large for this platform or index width")
            }
            TableError::BadQuantParams { param, value } => {
                write!(f, "bad quantization parameter {param:?}: {value}")
            }
            TableError::CrcMismatch { stored, computed } => {
                write!(f, "table CRC mismatch: stored {stored:#010x}, computed {computed:#010x}")
            }
            TableError::NonMonotoneOffsets { array, position } => {
                write!(
                    f,
                    "offsets in {array:?} not monotone or not ending at the count, at position {position}"
                )
            }
            TableError::IndexOutOfRange { array, position, index, bound } => {
                write!(f, "index {index} out of range (< {bound}) in {array:?} at position {position}")
            }
            TableError::UnsortedRow { row } => {
                write!(f, "form-factor row {row}: receivers not strictly increasing")
            }
            TableError::RowSumExceedsOne { row } => write!(f, "form-factor row {row}: decoded sum exceeds 1"),
            TableError::BadArea { patch } => write!(f, "patch {patch}: area not finite and positive"),
            TableError::BadIntensity { group } => {
                write!(f, "light group {group}: default intensity not finite")
            }
            TableError::TransferWithoutSolvedBase => {
                write!(f, "transfer basis present but the static base is not solved")
            }
            TableError::StateCountExceedsPatches { state_count, patch_count } => {
                write!(f, "state count {state_count} exceeds the patch count {patch_count}")
            }
            TableError::StateWithoutSolvedBase => {
                write!(f, "some patches have no run-time state but the static base is not solved")
            }
            TableError::UnsortedStateMap { slot } => {
                write!(f, "state map: patch of slot {slot} not above the previous slot's")
            }
            TableError::StateMaterialMismatch { slot } => {
                write!(f, "state map: material of slot {slot} differs from its patch's")
            }
            TableError::MemberWithoutState { position, patch } => {
                write!(f, "light-group member {position}: patch {patch} has no run-time state")
            }
            TableError::HierarchicalTable => {
                write!(
                    f,
                    "a hierarchical table (format version {}): read it with HierTable::parse",
                    super::HIER_FORMAT_VERSION
                )
            }
            TableError::FlatTable => write!(f, "a flat table (format version 3): read it with Table::parse"),
            TableError::BadTree { node, fault } => write!(f, "node tree: node {node}: {fault:?}"),
            TableError::NodeAreaMismatch { node } => {
                write!(f, "node {node}: area differs from the sum of its children's")
            }
            TableError::ChainSumExceedsOne { leaf } => {
                write!(f, "leaf {leaf}: decoded run sums over the leaf and its ancestors exceed 1")
            }
            TableError::BadMemberEmission { member } => {
                write!(f, "light-group member {member}: emission negative, not finite or too large")
            }
        }
    }
}

impl core::error::Error for TableError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_name_every_variant_once_in_order() {
        let one_of_each = [
            TableError::BadMagic { found: [0; 4] },
            TableError::UnsupportedVersion { found: 0, expected: 3 },
            TableError::BadHeader,
            TableError::TruncatedHeader,
            TableError::Truncated { expected: 1, actual: 0 },
            TableError::TrailingBytes { expected: 0, actual: 1 },
            TableError::CountsTooLarge,
            TableError::BadQuantParams { param: QuantParam::FfBits, value: 0 },
            TableError::CrcMismatch { stored: 0, computed: 1 },
            TableError::NonMonotoneOffsets { array: OffsetArray::RowStart, position: 0 },
            TableError::IndexOutOfRange { array: IndexArray::StatePatch, position: 0, index: 1, bound: 1 },
            TableError::UnsortedRow { row: 0 },
            TableError::RowSumExceedsOne { row: 0 },
            TableError::BadArea { patch: 0 },
            TableError::BadIntensity { group: 0 },
            TableError::TransferWithoutSolvedBase,
            TableError::StateCountExceedsPatches { state_count: 2, patch_count: 1 },
            TableError::StateWithoutSolvedBase,
            TableError::UnsortedStateMap { slot: 0 },
            TableError::StateMaterialMismatch { slot: 0 },
            TableError::MemberWithoutState { position: 0, patch: 0 },
            TableError::HierarchicalTable,
            TableError::FlatTable,
            TableError::BadTree { node: 0, fault: TreeFault::Parent },
            TableError::NodeAreaMismatch { node: 0 },
            TableError::ChainSumExceedsOne { leaf: 0 },
            TableError::BadMemberEmission { member: 0 },
        ];
        assert_eq!(one_of_each.map(|e| e.kind()), TableError::KINDS);
        for (i, a) in TableError::KINDS.iter().enumerate() {
            assert!(!TableError::KINDS[..i].contains(a), "{a} twice");
        }
    }
}
