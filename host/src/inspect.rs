//! Inspecting a table: validates it with core's [`Table::parse`] and reports its header, counts, section sizes
//! and statistics, for a terminal ([`fmt::Display`]) or as JSON (serde).
//!
//! Section sizes are core's [`Table::section_sizes`] (the layout of `docs/format.md`), grouped.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::rgb::{channel_max, Rgb};
use crate::text::counted;
use radiosity_core::codec::decode_emission_f32;
use radiosity_core::{Table, TableError, FORMAT_VERSION};
use serde::Serialize;
use thiserror::Error;

/// The counts of a table that fix its section sizes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct TableCounts {
    /// Patches `n`.
    pub patches: usize,
    /// Patches with run-time state `s <= n` (core's crate docs, "Run-time state"): the rows and solver
    /// buffers are sized by it.
    pub state: usize,
    /// Materials `m`.
    pub materials: usize,
    /// Light groups `g`.
    pub groups: usize,
    /// Light-group members `M`.
    pub members: usize,
    /// Form-factor entries `nnz`.
    pub entries: usize,
    /// Bytes per patch index (2 if `n <= 65536`, else 4).
    pub index_bytes: usize,
    /// Bytes per form-factor code.
    pub code_bytes: usize,
    /// Whether the table carries the transfer basis sections.
    pub transfer: bool,
}

impl TableCounts {
    /// The counts of a parsed table.
    #[must_use]
    pub fn of(table: &Table<'_>) -> TableCounts {
        let n = table.patch_count() as usize;
        let members = (0..table.group_count())
            .filter_map(|g| table.group_members(g))
            .map(|r| (r.end - r.start) as usize)
            .sum();
        TableCounts {
            patches: n,
            state: table.state_count() as usize,
            materials: table.material_count() as usize,
            groups: table.group_count() as usize,
            members,
            entries: table.entry_count() as usize,
            index_bytes: if n <= 0x1_0000 { 2 } else { 4 },
            code_bytes: table.codec().code_bytes(),
            transfer: table.has_transfer(),
        }
    }
}

/// Bytes of each part of a table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SectionBytes {
    /// Postcard header.
    pub header: usize,
    /// Patch areas, materials, static emission and static irradiance.
    pub patches: usize,
    /// Material reflectances.
    pub materials: usize,
    /// Light-group ids, default intensities and member starts.
    pub groups: usize,
    /// Member patches and their unit emission.
    pub members: usize,
    /// The state map (patch and material per slot); 0 when every patch has state.
    pub state_map: usize,
    /// Row starts and row exponents (per patch with state).
    pub rows: usize,
    /// Entry receivers.
    pub entry_receivers: usize,
    /// Entry form-factor codes.
    pub entry_codes: usize,
    /// Transfer basis: scale exponents (3 per group) and response codes (6 bytes per patch and group); 0 without.
    pub transfer: usize,
    /// Everything between header and CRC.
    pub payload: usize,
    /// The CRC-32.
    pub crc: usize,
    /// The whole table.
    pub total: usize,
}

impl SectionBytes {
    /// Section sizes of a parsed table, grouped from core's [`Table::section_sizes`].
    #[must_use]
    pub fn of(table: &Table<'_>) -> SectionBytes {
        let s = table.section_sizes();
        SectionBytes {
            header: s.header,
            patches: s.patch_area + s.patch_material + s.base_emission + s.base_irradiance,
            materials: s.reflectance,
            groups: s.group_id + s.group_intensity + s.group_start,
            members: s.member_patch + s.member_emission,
            state_map: s.state_patch + s.state_material,
            rows: s.row_start + s.row_exponent,
            entry_receivers: s.entry_receiver,
            entry_codes: s.entry_code,
            transfer: s.transfer_exponent + s.transfer_code,
            payload: s.payload(),
            crc: s.crc,
            total: s.total(),
        }
    }
}

impl fmt::Display for SectionBytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "  header {} | patches {} | materials {} | groups {} | members {} | state map {} | rows {} | receivers {} | codes {} | transfer {} | crc {}",
            self.header,
            self.patches,
            self.materials,
            self.groups,
            self.members,
            self.state_map,
            self.rows,
            self.entry_receivers,
            self.entry_codes,
            self.transfer,
            self.crc
        )
    }
}

/// Minimum, mean and maximum of a per-row statistic.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Stats {
    /// Minimum.
    pub min: f64,
    /// Mean.
    pub mean: f64,
    /// Maximum.
    pub max: f64,
}

impl Stats {
    fn of(values: impl Iterator<Item = f64>) -> Stats {
        let (mut min, mut max, mut sum, mut count) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
        for v in values {
            min = min.min(v);
            max = max.max(v);
            sum += v;
            count += 1;
        }
        if count == 0 {
            return Stats { min: 0.0, mean: 0.0, max: 0.0 };
        }
        Stats { min, mean: sum / count as f64, max }
    }
}

/// One light group of a table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GroupInfo {
    /// Position in the table.
    pub index: u32,
    /// Identifier (a bake uses FNV-1a of the group name, [`radiosity_core::group_id`]).
    pub id: u32,
    /// The group's name, when known: a name given to [`InspectReport::name_groups`] whose id is `id` (the table
    /// itself stores only the id).
    pub name: Option<String>,
    /// Member patches.
    pub members: u32,
    /// Default intensity (RGB).
    pub default_intensity: [f32; 3],
}

/// What [`inspect`] found in a valid table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InspectReport {
    /// Format version (always [`FORMAT_VERSION`] for a table that parses).
    pub version: u16,
    /// CRC-32 of the table.
    pub crc: u32,
    /// Scene fingerprint from the header (`bake::scene_fingerprint` of the patches it was baked from).
    pub fingerprint: u64,
    /// Counts.
    pub counts: TableCounts,
    /// Codec name.
    pub codec: String,
    /// Form-factor code width in bits.
    pub ff_bits: u8,
    /// Form-factor exponent bits.
    pub ff_exponent_bits: u8,
    /// Whether the static base is solved.
    pub base_solved: bool,
    /// Bytes per section.
    pub bytes: SectionBytes,
    /// Entries per row (rows of patches with state).
    pub row_len: Stats,
    /// Decoded row sums.
    pub row_sum: Stats,
    /// Rows with no entries.
    pub empty_rows: usize,
    /// Total patch area (scene units squared).
    pub total_area: f64,
    /// Patches with nonzero static emission.
    pub static_emitters: usize,
    /// Light groups.
    pub groups: Vec<GroupInfo>,
    /// The transfer basis section, if present.
    pub transfer: Option<TransferInfo>,
}

/// The transfer basis section of a table (core's `transfer` module).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TransferInfo {
    /// Bytes of the section.
    pub bytes: usize,
    /// Per light group, the scale `2^K` of its codes per channel (W/m^2 per unit intensity); a response `T`
    /// is within `max(2^-13 T, 2^(K - 27))` of the host's f64 value.
    pub scale: Vec<Rgb>,
    /// Per light group, the largest decoded response per channel (W/m^2 per unit intensity).
    pub max_response: Vec<Rgb>,
}

impl InspectReport {
    /// Names every light group whose id is the [`radiosity_core::group_id`] of one of `names` (e.g. the light groups
    /// of the scene the table was baked from: `radiosity inspect TABLE --scene SCENE.obj`); names that match no
    /// group are ignored. Returns how many groups have a name afterwards.
    pub fn name_groups<'a>(&mut self, names: impl IntoIterator<Item = &'a str>) -> usize {
        for name in names {
            let id = radiosity_core::group_id(name);
            for g in self.groups.iter_mut().filter(|g| g.id == id) {
                g.name = Some(name.to_owned());
            }
        }
        self.groups.iter().filter(|g| g.name.is_some()).count()
    }
}

impl fmt::Display for InspectReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = &self.counts;
        writeln!(f, "table format v{}  crc {:#010x}  valid", self.version, self.crc)?;
        writeln!(f, "fingerprint  {:#018x} (scene and meshing)", self.fingerprint)?;
        writeln!(f, "patches      {} (total area {:.6e})", c.patches, self.total_area)?;
        writeln!(
            f,
            "state        {} of {} patches carry run-time state{}",
            c.state,
            c.patches,
            if c.state < c.patches { " (the others show the static base)" } else { "" }
        )?;
        writeln!(f, "materials    {}", c.materials)?;
        let unnamed = self.groups.iter().any(|g| g.name.is_none());
        writeln!(
            f,
            "light groups {} ({}{})",
            c.groups,
            counted(c.members, "member", "members"),
            if unnamed { "; names: inspect TABLE --scene SCENE.obj" } else { "" }
        )?;
        for g in &self.groups {
            let name = g.name.as_ref().map_or_else(String::new, |n| format!(" {n:?}"));
            writeln!(
                f,
                "  group {:<3} id {:#010x}{name}  {}  default {:?}",
                g.index,
                g.id,
                counted(g.members as usize, "member", "members"),
                g.default_intensity
            )?;
        }
        writeln!(
            f,
            "static base  {} ({})",
            if self.base_solved { "solved" } else { "unsolved" },
            counted(self.static_emitters, "emitting patch", "emitting patches")
        )?;
        writeln!(
            f,
            "entries      {} ({}, {} bits, {} exponent bits, {}-byte indices)",
            c.entries, self.codec, self.ff_bits, self.ff_exponent_bits, c.index_bytes
        )?;
        writeln!(
            f,
            "row length   min {} mean {:.2} max {} ({})",
            self.row_len.min,
            self.row_len.mean,
            self.row_len.max,
            counted(self.empty_rows, "empty row", "empty rows")
        )?;
        writeln!(
            f,
            "row sum      min {:.6} mean {:.6} max {:.6}",
            self.row_sum.min, self.row_sum.mean, self.row_sum.max
        )?;
        if let Some(t) = &self.transfer {
            writeln!(
                f,
                "transfer     basis for {} x {}, {} bytes",
                counted(c.groups, "group", "groups"),
                counted(c.patches, "patch", "patches"),
                t.bytes
            )?;
            for (g, (scale, max)) in t.scale.iter().zip(&t.max_response).enumerate() {
                writeln!(
                    f,
                    "  group {g:<3} scale {:.3e} {:.3e} {:.3e}  max response {:.3e} {:.3e} {:.3e}",
                    scale[0], scale[1], scale[2], max[0], max[1], max[2]
                )?;
            }
        } else {
            writeln!(f, "transfer     none")?;
        }
        writeln!(f, "bytes        {}", self.bytes.total)?;
        write!(f, "{}", self.bytes)
    }
}

/// Why a table could not be inspected.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum InspectError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Core rejected the table.
    #[error("{source_name}: invalid table: {error}")]
    Table {
        /// Where the bytes came from (a path, or `<bytes>`).
        source_name: String,
        /// Core's error.
        error: TableError,
    },
}

/// Validates `bytes` with [`Table::parse`] and reports on the table.
///
/// # Errors
/// [`InspectError::Table`] with core's error (source named `<bytes>`).
pub fn inspect(bytes: &[u8]) -> Result<InspectReport, InspectError> {
    inspect_named(bytes, "<bytes>")
}

/// Reads the table file at `path` and inspects it; errors name the file.
///
/// # Errors
/// [`InspectError::Io`] if the file cannot be read, [`InspectError::Table`] if core rejects it.
pub fn inspect_file(path: &Path) -> Result<InspectReport, InspectError> {
    let bytes =
        std::fs::read(path).map_err(|source| InspectError::Io { path: path.to_path_buf(), source })?;
    inspect_named(&bytes, &path.display().to_string())
}

fn inspect_named(bytes: &[u8], name: &str) -> Result<InspectReport, InspectError> {
    let table =
        Table::parse(bytes).map_err(|error| InspectError::Table { source_name: name.to_string(), error })?;
    let counts = TableCounts::of(&table);
    let n = table.patch_count();
    let slots = table.state_count();
    let row_lens: Vec<f64> =
        (0..slots).filter_map(|i| table.row(i)).map(|r| f64::from(r.end - r.start)).collect();
    let groups = (0..table.group_count())
        .map(|g| GroupInfo {
            index: g,
            id: table.group_id(g).unwrap_or(0),
            name: None,
            members: table.group_members(g).map_or(0, |r| r.end - r.start),
            default_intensity: table.default_intensity(g).unwrap_or([0.0; 3]),
        })
        .collect();
    let codec = table.codec();
    let bytes_of = SectionBytes::of(&table);
    let transfer = table.has_transfer().then(|| TransferInfo {
        bytes: bytes_of.transfer,
        scale: (0..table.group_count())
            .map(|g| {
                Rgb::from_array(table.transfer_exponent(g).unwrap_or([0; 3]).map(|k| 2f64.powi(i32::from(k))))
            })
            .collect(),
        max_response: (0..table.group_count())
            .map(|g| {
                (0..n).fold(Rgb::ZERO, |m, i| {
                    let r = table.transfer_response(i, g).unwrap_or([0.0; 3]);
                    channel_max(m, Rgb::from_array(r.map(f64::from)))
                })
            })
            .collect(),
    });
    Ok(InspectReport {
        version: FORMAT_VERSION,
        crc: table.crc(),
        fingerprint: table.fingerprint(),
        counts,
        codec: codec.to_string(),
        ff_bits: codec.bits,
        ff_exponent_bits: codec.exponent_bits,
        base_solved: table.base_solved(),
        bytes: bytes_of,
        row_len: Stats::of(row_lens.iter().copied()),
        row_sum: Stats::of((0..slots).filter_map(|i| table.row_sum(i)).map(f64::from)),
        empty_rows: row_lens.iter().filter(|&&l| l == 0.0).count(),
        total_area: (0..n).filter_map(|i| table.area(i)).map(f64::from).sum(),
        static_emitters: (0..n)
            .filter_map(|i| table.base_emission(i))
            .filter(|e| e.iter().any(|&c| decode_emission_f32(c) > 0.0))
            .count(),
        groups,
        transfer,
    })
}
