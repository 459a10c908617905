//! Relight scripts: the TOML format, its parser and validation, and the Rust code the firmware compiles in.
//!
//! # Format (`scenes/*.relight.toml`)
//! The user reference, with an annotated example of every field, is `docs/relight-scripts.md` (a test parses
//! every example in it). In short:
//! ```toml
//! [[script]]
//! name = "lights-on"            # letters, digits, '-', '_'; unique in the file
//! description = "..."           # optional
//! tolerance = 1e-3              # convergence tolerance, relative to the lights' total power at unit intensity
//! budget = 400                  # default per-frame budget in work units (optional if every frame has one)
//! boot_budget = 1000000         # optional (default 10_000_000): units the boot solve may spend
//! initial = { light = [0.0, 0.0, 0.0] }  # intensity (RGB) of every light group by name, solved at boot
//!
//! [[script.frame]]
//! intensity = { light = [1.0, 1.0, 1.0] } # optional: absolute intensities from this frame on (default: unchanged)
//! budget = 400                  # optional: overrides the script's budget
//! repeat = 10                   # optional (default 1): this frame this many times
//! ramp = false                  # optional: with `repeat = N`, step linearly from the previous intensity
//!                               # to `intensity` over the N frames (frame k of N at prev + (target - prev) k / N)
//! ```
//! Intensities are given by light-group name (a table keyed by the name, as the scene calls the group) or by
//! position (`initial = [[0.0, 0.0, 0.0]]`, one RGB array per light group in table order); one script uses one
//! form. A named `initial` must name every dynamic light group of the table; a named frame changes only the
//! groups it names. A name stands for the table's group whose id is [`radiosity_core::group_id`] of the name,
//! so [`ScriptFile::resolve`] needs only the table ([`TableGroups`]).
//! A light group keeps its intensity until a frame names a new one; the device calls `set_light` only for
//! groups whose intensity changed. Intensities must be finite and non-negative; budgets at least 1.

use std::fmt::{self, Write as _};

use serde::Deserialize;

use crate::device::{DeviceTable, Frame, Script};

/// Default boot budget (work units) when a script gives none.
pub const DEFAULT_BOOT_BUDGET: u32 = 10_000_000;

/// A parse or validation error, naming the file, script and frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ScriptError(pub String);

impl fmt::Display for ScriptError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ScriptError {}

/// `names` quoted and comma-separated, for messages.
fn quoted(names: &[String]) -> String {
    names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlFile {
    script: Vec<TomlScript>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlScript {
    name: String,
    #[serde(default)]
    description: String,
    tolerance: f64,
    budget: Option<u32>,
    boot_budget: Option<u32>,
    /// An array of RGB arrays (table order) or a table of them keyed by light-group name; see [`entry`].
    initial: toml::Value,
    #[serde(default)]
    frame: Vec<TomlFrame>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlFrame {
    /// As [`TomlScript::initial`].
    intensity: Option<toml::Value>,
    budget: Option<u32>,
    repeat: Option<u32>,
    #[serde(default)]
    ramp: bool,
}

/// One frame of a parsed script (owned).
#[derive(Clone, Debug, PartialEq)]
pub struct OwnedFrame {
    /// Budget in work units.
    pub budget: u32,
    /// Intensity of every light group, in the order of [`OwnedScript::groups`].
    pub intensity: Vec<[f32; 3]>,
}

/// A parsed and expanded script (owned); [`OwnedScript::with_view`] lends it as a device [`Script`].
#[derive(Clone, Debug, PartialEq)]
pub struct OwnedScript {
    /// Name.
    pub name: String,
    /// Description.
    pub description: String,
    /// Convergence tolerance, relative to the lights' power at unit intensity ([`Script::tolerance`]).
    pub tolerance: f32,
    /// Boot budget (work units).
    pub boot_budget: u32,
    /// The light groups the intensities refer to, by name, in the order of every intensity vector: the names
    /// `initial` gives (sorted) for a script that names its groups, then, after [`ScriptFile::resolve`], the
    /// table's order. `None`: the script gives intensities by position, in table order.
    pub groups: Option<Vec<String>>,
    /// Initial intensities.
    pub initial: Vec<[f32; 3]>,
    /// Frames, with `repeat` and `ramp` expanded.
    pub frames: Vec<OwnedFrame>,
}

impl OwnedScript {
    /// Calls `f` with a borrowed device view of the script.
    pub fn with_view<R>(&self, f: impl FnOnce(&Script<'_>) -> R) -> R {
        let frames: Vec<Frame<'_>> =
            self.frames.iter().map(|fr| Frame { budget: fr.budget, intensity: &fr.intensity }).collect();
        f(&Script {
            name: &self.name,
            tolerance: self.tolerance,
            initial: &self.initial,
            boot_budget: self.boot_budget,
            frames: &frames,
        })
    }
}

/// A parsed relight script file.
#[derive(Clone, Debug, PartialEq)]
pub struct ScriptFile {
    /// The scripts, in file order.
    pub scripts: Vec<OwnedScript>,
}

/// The light groups of a table, which scripts' group names are resolved against: each group's id and, where
/// the caller knows it (from the scene the table was baked from), its name.
///
/// A name in a script stands for the group whose id is [`radiosity_core::group_id`] of the name, so names
/// resolve against the table alone; the known names only make messages readable.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TableGroups {
    ids: Vec<u32>,
    names: Vec<Option<String>>,
}

impl TableGroups {
    /// The groups of `table` (either format), names unknown.
    #[must_use]
    pub fn of<'a>(table: &impl DeviceTable<'a>) -> TableGroups {
        let ids: Vec<u32> = (0..table.group_count()).filter_map(|g| table.group_id(g)).collect();
        let names = vec![None; ids.len()];
        TableGroups { ids, names }
    }

    /// Groups with these ids, in this order, names unknown.
    #[must_use]
    pub fn from_ids(ids: Vec<u32>) -> TableGroups {
        let names = vec![None; ids.len()];
        TableGroups { ids, names }
    }

    /// Names every group whose id is [`radiosity_core::group_id`] of one of `candidates` (e.g. the scene's
    /// light-group names); candidates that match no group are ignored.
    #[must_use]
    pub fn named<'a>(mut self, candidates: impl IntoIterator<Item = &'a str>) -> TableGroups {
        for name in candidates {
            if let Some(g) = self.ids.iter().position(|&id| id == radiosity_core::group_id(name)) {
                self.names[g] = Some(name.to_owned());
            }
        }
        self
    }

    /// Number of groups.
    #[must_use]
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// Whether the table has no light groups.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The id of group `g` (table order).
    #[must_use]
    pub fn id(&self, g: usize) -> Option<u32> {
        self.ids.get(g).copied()
    }

    /// The name of group `g`, if known.
    #[must_use]
    pub fn name(&self, g: usize) -> Option<&str> {
        self.names.get(g).and_then(|n| n.as_deref())
    }

    /// The group named `name`: the one whose id is its [`radiosity_core::group_id`].
    #[must_use]
    pub fn find(&self, name: &str) -> Option<usize> {
        self.ids.iter().position(|&id| id == radiosity_core::group_id(name))
    }

    /// Group `g` for a message: its name in quotes if known, else its position and id.
    #[must_use]
    pub fn label(&self, g: usize) -> String {
        match self.name(g) {
            Some(n) => format!("\"{n}\""),
            None => format!("group {g} (id {:#010x})", self.id(g).unwrap_or(0)),
        }
    }

    /// Every group for a message, comma-separated ([`TableGroups::label`]).
    #[must_use]
    pub fn list(&self) -> String {
        if self.ids.is_empty() {
            return "none".to_owned();
        }
        (0..self.ids.len()).map(|g| self.label(g)).collect::<Vec<_>>().join(", ")
    }
}

/// The intensities of one `initial` or `intensity` entry, as written.
enum Entry {
    /// One RGB intensity per light group, in table order.
    Positional(Vec<[f32; 3]>),
    /// RGB intensities by light-group name (sorted by name).
    Named(Vec<(String, [f32; 3])>),
}

/// Reads an `initial` or `intensity` value: an array of RGB arrays (one per light group, table order) or a table
/// of RGB arrays keyed by light-group name. Every channel must be finite, non-negative and fit an `f32`.
fn entry(v: &toml::Value, at: &dyn Fn() -> String) -> Result<Entry, ScriptError> {
    let rgb = |x: &toml::Value, group: &str| -> Result<[f32; 3], ScriptError> {
        // `what` continues "intensity of light group NAME" (", channel ..." or ": ...").
        let bad = |what: String| ScriptError(format!("{}: intensity of light group {group}{what}", at()));
        let toml::Value::Array(a) = x else {
            return Err(bad(format!(": {x} is not an array of 3 numbers (R, G, B)")));
        };
        if a.len() != 3 {
            return Err(bad(format!(": {x} has {} numbers, not 3 (R, G, B)", a.len())));
        }
        let mut out = [0.0f32; 3];
        for (c, value) in a.iter().enumerate() {
            let number = value.as_float().or_else(|| value.as_integer().map(|i| i as f64));
            match number {
                Some(n) if n.is_finite() && n >= 0.0 && n <= f64::from(f32::MAX) => out[c] = n as f32,
                _ => return Err(bad(format!(", channel {c}: {value} is not a finite non-negative number"))),
            }
        }
        Ok(out)
    };
    match v {
        toml::Value::Array(groups) => {
            if groups.is_empty() {
                return Err(ScriptError(format!("{}: no light-group intensities", at())));
            }
            let out: Result<Vec<_>, _> =
                groups.iter().enumerate().map(|(g, x)| rgb(x, &g.to_string())).collect();
            out.map(Entry::Positional)
        }
        toml::Value::Table(groups) => {
            if groups.is_empty() {
                return Err(ScriptError(format!("{}: no light-group intensities", at())));
            }
            let out: Result<Vec<_>, _> =
                groups.iter().map(|(name, x)| Ok((name.clone(), rgb(x, &format!("\"{name}\""))?))).collect();
            out.map(Entry::Named)
        }
        other => Err(ScriptError(format!(
            "{}: {other} is neither an array of RGB intensities (one per light group, in table order) nor a \
             table of them by light-group name",
            at()
        ))),
    }
}

impl ScriptFile {
    /// Parses and validates a script file's text; `origin` (a path) names it in errors.
    ///
    /// Scripts that name their light groups keep the names ([`OwnedScript::groups`]); [`ScriptFile::resolve`]
    /// puts their intensities in a table's order.
    ///
    /// # Errors
    /// A [`ScriptError`] naming the file, script and frame of the first problem.
    pub fn parse(text: &str, origin: &str) -> Result<ScriptFile, ScriptError> {
        let file: TomlFile =
            toml::from_str(text).map_err(|e| ScriptError(format!("{origin}: not a relight script: {e}")))?;
        if file.script.is_empty() {
            return Err(ScriptError(format!("{origin}: no [[script]]")));
        }
        let mut scripts: Vec<OwnedScript> = Vec::new();
        for (si, s) in file.script.iter().enumerate() {
            let here = format!("{origin}: script {si} (\"{}\")", s.name);
            if s.name.is_empty() || !s.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
            {
                return Err(ScriptError(format!("{here}: name must be letters, digits, '-' or '_'")));
            }
            if scripts.iter().any(|o| o.name == s.name) {
                return Err(ScriptError(format!("{here}: duplicate script name")));
            }
            if !(s.tolerance.is_finite() && s.tolerance > 0.0 && s.tolerance < f64::from(f32::MAX)) {
                return Err(ScriptError(format!(
                    "{here}: tolerance {} must be finite and positive",
                    s.tolerance
                )));
            }
            let boot_budget = s.boot_budget.unwrap_or(DEFAULT_BOOT_BUDGET);
            if boot_budget == 0 {
                return Err(ScriptError(format!("{here}: boot_budget must be at least 1")));
            }
            let (groups, initial) = match entry(&s.initial, &|| format!("{here}: initial"))? {
                Entry::Positional(v) => (None, v),
                Entry::Named(v) => {
                    let (names, values): (Vec<String>, Vec<[f32; 3]>) = v.into_iter().unzip();
                    (Some(names), values)
                }
            };
            if s.frame.is_empty() {
                return Err(ScriptError(format!("{here}: no [[script.frame]]")));
            }
            let mut frames: Vec<OwnedFrame> = Vec::new();
            let mut current = initial.clone();
            for (fi, f) in s.frame.iter().enumerate() {
                let at = || format!("{here}: [[script.frame]] {fi} (expanded frame {})", frames.len());
                let budget = f.budget.or(s.budget).ok_or_else(|| {
                    ScriptError(format!("{}: no budget (set it on the frame or the script)", at()))
                })?;
                if budget == 0 {
                    return Err(ScriptError(format!("{}: budget must be at least 1 work unit", at())));
                }
                let repeat = f.repeat.unwrap_or(1);
                if repeat == 0 {
                    return Err(ScriptError(format!("{}: repeat must be at least 1", at())));
                }
                let target = match (&f.intensity, &groups) {
                    (Some(v), _) => match (entry(v, &at)?, &groups) {
                        (Entry::Positional(v), None) => v,
                        (Entry::Named(v), Some(names)) => {
                            // Named groups change; the others keep their intensity.
                            let mut target = current.clone();
                            for (name, rgb) in v {
                                let Some(g) = names.iter().position(|n| *n == name) else {
                                    return Err(ScriptError(format!(
                                        "{}: light group \"{name}\" is not in `initial`, which names {}",
                                        at(),
                                        quoted(names)
                                    )));
                                };
                                target[g] = rgb;
                            }
                            target
                        }
                        (Entry::Positional(_), Some(_)) => {
                            return Err(ScriptError(format!(
                                "{}: intensities by position, but `initial` names the light groups: use \
                                 names here too ({{ name = [r, g, b] }})",
                                at()
                            )));
                        }
                        (Entry::Named(_), None) => {
                            return Err(ScriptError(format!(
                                "{}: intensities by name, but `initial` gives them by position: name the \
                                 light groups in `initial` too",
                                at()
                            )));
                        }
                    },
                    (None, _) if f.ramp => {
                        return Err(ScriptError(format!("{}: ramp needs an intensity to ramp to", at())));
                    }
                    (None, _) => current.clone(),
                };
                if target.len() != current.len() {
                    return Err(ScriptError(format!(
                        "{}: {} light-group intensities, the initial state has {}",
                        at(),
                        target.len(),
                        current.len()
                    )));
                }
                for k in 1..=repeat {
                    let intensity = if f.ramp {
                        // Interpolated in f64 and rounded once, so the frames are the same on every machine.
                        let t = f64::from(k) / f64::from(repeat);
                        current
                            .iter()
                            .zip(&target)
                            .map(|(a, b)| {
                                [0, 1, 2].map(|c| {
                                    (f64::from(a[c]) + (f64::from(b[c]) - f64::from(a[c])) * t) as f32
                                })
                            })
                            .collect()
                    } else {
                        target.clone()
                    };
                    frames.push(OwnedFrame { budget, intensity });
                }
                current = target;
            }
            scripts.push(OwnedScript {
                name: s.name.clone(),
                description: s.description.clone(),
                tolerance: s.tolerance as f32,
                boot_budget,
                groups,
                initial,
                frames,
            });
        }
        Ok(ScriptFile { scripts })
    }

    /// Reads and parses a script file.
    ///
    /// # Errors
    /// The file cannot be read, or [`ScriptFile::parse`] fails.
    pub fn load(path: &std::path::Path) -> Result<ScriptFile, ScriptError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ScriptError(format!("{}: cannot read: {e}", path.display())))?;
        ScriptFile::parse(&text, &path.display().to_string())
    }

    /// The file with every script's intensities in the order of the table's light groups `groups`: a script
    /// that names its groups gets them reordered (a name stands for the group whose id is its
    /// [`radiosity_core::group_id`]); a positional one must give one intensity per group.
    ///
    /// # Errors
    /// A [`ScriptError`] naming the first script that gives the wrong number of intensities, names a group
    /// the table does not have (listing the table's groups), or leaves one of the table's groups out.
    pub fn resolve(&self, groups: &TableGroups) -> Result<ScriptFile, ScriptError> {
        let mut scripts = Vec::with_capacity(self.scripts.len());
        for s in &self.scripts {
            let Some(names) = &s.groups else {
                if s.initial.len() != groups.len() {
                    return Err(ScriptError(format!(
                        "script \"{}\": {} light-group intensities, the table has {} light groups ({}); or \
                         name them: initial = {{ name = [r, g, b] }}",
                        s.name,
                        s.initial.len(),
                        groups.len(),
                        groups.list()
                    )));
                }
                scripts.push(s.clone());
                continue;
            };
            // order[g]: the script's index of table group g.
            let mut order: Vec<Option<usize>> = vec![None; groups.len()];
            for (k, name) in names.iter().enumerate() {
                let Some(g) = groups.find(name) else {
                    return Err(ScriptError(format!(
                        "script \"{}\": the table has no light group \"{name}\" (id {:#010x}); its light groups: {}",
                        s.name,
                        radiosity_core::group_id(name),
                        groups.list()
                    )));
                };
                order[g] = Some(k);
            }
            let missing: Vec<String> =
                (0..groups.len()).filter(|&g| order[g].is_none()).map(|g| groups.label(g)).collect();
            if !missing.is_empty() {
                return Err(ScriptError(format!(
                    "script \"{}\": `initial` leaves out the table's light group{} {} (it names {})",
                    s.name,
                    if missing.len() == 1 { "" } else { "s" },
                    missing.join(", "),
                    quoted(names)
                )));
            }
            let order: Vec<usize> = order.into_iter().flatten().collect();
            let reorder = |v: &[[f32; 3]]| order.iter().map(|&k| v[k]).collect::<Vec<_>>();
            scripts.push(OwnedScript {
                groups: Some(order.iter().map(|&k| names[k].clone()).collect()),
                initial: reorder(&s.initial),
                frames: s
                    .frames
                    .iter()
                    .map(|f| OwnedFrame { budget: f.budget, intensity: reorder(&f.intensity) })
                    .collect(),
                ..s.clone()
            });
        }
        Ok(ScriptFile { scripts })
    }

    /// The script named `name`.
    #[must_use]
    pub fn get(&self, name: &str) -> Option<&OwnedScript> {
        self.scripts.iter().find(|s| s.name == name)
    }

    /// Rust source declaring `pub static SCRIPTS: &[Script<'static>]` with every script as const data (f32
    /// values written as exact bits), for the firmware's build script. Paths: `firmware_sim::device`.
    #[must_use]
    pub fn to_rust(&self) -> String {
        let rgb = |v: &[[f32; 3]]| {
            let mut s = String::from("&[");
            for x in v {
                let _ = write!(
                    s,
                    "[f32::from_bits(0x{:08x}), f32::from_bits(0x{:08x}), f32::from_bits(0x{:08x})],",
                    x[0].to_bits(),
                    x[1].to_bits(),
                    x[2].to_bits()
                );
            }
            s.push(']');
            s
        };
        let mut out = String::from(
            "// Generated from a relight script file by firmware-sim's `ScriptFile::to_rust`.\n",
        );
        out.push_str("pub static SCRIPTS: &[firmware_sim::device::Script<'static>] = &[\n");
        for s in &self.scripts {
            let _ = writeln!(
                out,
                "    firmware_sim::device::Script {{ name: {:?}, tolerance: f32::from_bits(0x{:08x}), initial: {}, \
                 boot_budget: {}, frames: &[",
                s.name,
                s.tolerance.to_bits(),
                rgb(&s.initial),
                s.boot_budget
            );
            for f in &s.frames {
                let _ = writeln!(
                    out,
                    "        firmware_sim::device::Frame {{ budget: {}, intensity: {} }},",
                    f.budget,
                    rgb(&f.intensity)
                );
            }
            out.push_str("    ] },\n");
        }
        out.push_str("];\n");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Frames as an array of inline tables: TOML's other spelling of `[[script.frame]]` sections (the scenes'
    // files use the sections), which the parser must take the same way.
    const OK: &str = r#"
[[script]]
name = "dim"
tolerance = 1e-3
budget = 100
initial = [[1.0, 1.0, 1.0]]
frame = [
    { intensity = [[0.0, 0.5, 1.0]], repeat = 4, ramp = true },
    { budget = 7 },
]
"#;

    #[test]
    fn ramp_and_repeat_expand() {
        let f = ScriptFile::parse(OK, "t.toml").unwrap();
        let s = &f.scripts[0];
        assert_eq!(s.frames.len(), 5);
        assert_eq!(s.frames[0].intensity, vec![[0.75, 0.875, 1.0]]);
        assert_eq!(s.frames[3].intensity, vec![[0.0, 0.5, 1.0]]);
        // The last frame keeps the ramp's target and overrides the budget.
        assert_eq!(s.frames[4], OwnedFrame { budget: 7, intensity: vec![[0.0, 0.5, 1.0]] });
        assert_eq!(f.resolve(&TableGroups::from_ids(vec![7])).unwrap(), f);
        let e = f.resolve(&TableGroups::from_ids(vec![7, 8])).unwrap_err().0;
        assert!(
            e.contains("the table has 2 light groups (group 0 (id 0x00000007), group 1 (id 0x00000008))"),
            "{e}"
        );
    }

    // Two light groups by name; `TWO_POSITIONAL` is the same script by position, for a table whose groups are
    // `lamp` then `ceiling` (the names are not in table order here: `resolve` reorders).
    const TWO_NAMED: &str = r#"
[[script]]
name = "two"
tolerance = 1e-3
budget = 50
initial = { lamp = [1.0, 1.0, 1.0], ceiling = [0.0, 0.0, 0.0] }
[[script.frame]]
intensity = { ceiling = [0.5, 0.5, 0.5] }
repeat = 2
ramp = true
[[script.frame]]
intensity = { lamp = [0.0, 0.0, 0.0], ceiling = [1.0, 0.5, 0.25] }
"#;
    const TWO_POSITIONAL: &str = r#"
[[script]]
name = "two"
tolerance = 1e-3
budget = 50
initial = [[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]
[[script.frame]]
intensity = [[1.0, 1.0, 1.0], [0.5, 0.5, 0.5]]
repeat = 2
ramp = true
[[script.frame]]
intensity = [[0.0, 0.0, 0.0], [1.0, 0.5, 0.25]]
"#;

    fn lamp_ceiling() -> TableGroups {
        let ids = vec![radiosity_core::group_id("lamp"), radiosity_core::group_id("ceiling")];
        TableGroups::from_ids(ids)
    }

    #[test]
    fn names_resolve_to_the_positional_script() {
        let named = ScriptFile::parse(TWO_NAMED, "t.toml").unwrap();
        let positional = ScriptFile::parse(TWO_POSITIONAL, "t.toml").unwrap();
        // Before resolution, a named script is in the order of its names (sorted): ceiling, lamp.
        assert_eq!(named.scripts[0].groups, Some(vec!["ceiling".to_owned(), "lamp".to_owned()]));
        assert_eq!(named.scripts[0].initial, vec![[0.0; 3], [1.0; 3]]);
        // Resolved against table order (lamp, ceiling), names or not, the frames are the same.
        let groups = lamp_ceiling();
        let (named, positional) = (named.resolve(&groups).unwrap(), positional.resolve(&groups).unwrap());
        let (a, b) = (&named.scripts[0], &positional.scripts[0]);
        assert_eq!(a.groups, Some(vec!["lamp".to_owned(), "ceiling".to_owned()]));
        assert_eq!(b.groups, None);
        assert_eq!((&a.initial, &a.frames), (&b.initial, &b.frames));
        // The unnamed group kept its intensity through the ramp.
        assert_eq!(a.frames[0].intensity, vec![[1.0; 3], [0.25; 3]]);
        assert_eq!(a.frames.len(), 3);
        // The firmware gets the same code from either.
        assert_eq!(named.to_rust(), positional.to_rust());
    }

    #[test]
    fn name_errors_list_the_groups() {
        let named = ScriptFile::parse(TWO_NAMED, "t.toml").unwrap();
        // Unknown name: the table's groups are listed by name where known, by id where not.
        let groups =
            TableGroups::from_ids(vec![radiosity_core::group_id("lamp"), radiosity_core::group_id("desk")])
                .named(["desk", "lamp", "unrelated"]);
        let e = named.resolve(&groups).unwrap_err().0;
        assert!(e.contains("the table has no light group \"ceiling\""), "{e}");
        assert!(e.contains("its light groups: \"lamp\", \"desk\""), "{e}");
        let e =
            named.resolve(&TableGroups::from_ids(vec![radiosity_core::group_id("lamp"), 9])).unwrap_err().0;
        assert!(e.contains("its light groups: group 0 (id 0x"), "{e}");
        // A table group the script leaves out.
        let three = lamp_ceiling().named(["lamp", "ceiling"]);
        let three = TableGroups::from_ids(vec![
            three.id(0).unwrap(),
            three.id(1).unwrap(),
            radiosity_core::group_id("desk"),
        ])
        .named(["lamp", "ceiling", "desk"]);
        let e = named.resolve(&three).unwrap_err().0;
        assert!(e.contains("`initial` leaves out the table's light group \"desk\""), "{e}");
        // At parse time: a frame naming a group `initial` does not, and mixed forms.
        let cases = [
            (
                TWO_NAMED.replace("{ ceiling = [0.5", "{ desk = [0.5"),
                "light group \"desk\" is not in `initial`, which names \"ceiling\", \"lamp\"",
            ),
            (
                TWO_NAMED.replace("{ ceiling = [0.5, 0.5, 0.5] }", "[[0.5, 0.5, 0.5]]"),
                "intensities by position, but `initial` names",
            ),
            (
                TWO_POSITIONAL.replace("[[0.0, 0.0, 0.0], [1.0, 0.5, 0.25]]", "{ lamp = [0.0, 0.0, 0.0] }"),
                "intensities by name, but `initial` gives them by position",
            ),
            (
                TWO_NAMED.replace("ceiling = [0.0, 0.0, 0.0]", "ceiling = [0.0, -1.0, 0.0]"),
                "light group \"ceiling\", channel 1: -1",
            ),
            (TWO_NAMED.replace("ceiling = [0.0, 0.0, 0.0]", "ceiling = [0.0, 0.0]"), "has 2 numbers, not 3"),
            (TWO_NAMED.replace("initial = {", "initial = 3 #"), "neither an array of RGB intensities"),
            (
                TWO_NAMED.replace(
                    "initial = { lamp = [1.0, 1.0, 1.0], ceiling = [0.0, 0.0, 0.0] }",
                    "initial = {}",
                ),
                "no light-group intensities",
            ),
        ];
        for (text, want) in cases {
            let e = ScriptFile::parse(&text, "t.toml").unwrap_err().0;
            assert!(e.contains(want), "error {e:?} does not contain {want:?}");
            assert!(
                e.starts_with("t.toml: script 0 (\"two\")"),
                "error {e:?} does not name the file and script"
            );
        }
    }

    #[test]
    fn errors_name_the_place() {
        let cases = [
            (OK.replace("budget = 100\n", ""), "[[script.frame]] 0 (expanded frame 0): no budget"),
            (OK.replace("budget = 7", "budget = 0"), "[[script.frame]] 1 (expanded frame 4): budget must be"),
            (OK.replace("[0.0, 0.5, 1.0]", "[0.0, -0.5, 1.0]"), "light group 0, channel 1: -0.5"),
            (OK.replace("repeat = 4", "repeat = 0"), "repeat must be at least 1"),
            (OK.replace("name = \"dim\"", "name = \"a b\""), "name must be"),
            (OK.replace("tolerance = 1e-3", "tolerance = 0.0"), "tolerance 0 must be"),
            (OK.replace("ramp = true", "ramp = true, speed = 2"), "unknown field `speed`"),
            (
                OK.replace("[[0.0, 0.5, 1.0]]", "[[0.0, 0.5, 1.0], [1.0, 1.0, 1.0]]"),
                "2 light-group intensities",
            ),
        ];
        for (text, want) in cases {
            let e = ScriptFile::parse(&text, "t.toml").unwrap_err().0;
            assert!(e.contains(want), "error {e:?} does not contain {want:?}");
            assert!(e.starts_with("t.toml"), "error {e:?} does not name the file");
        }
    }

    #[test]
    fn rust_code_carries_exact_bits() {
        let f = ScriptFile::parse(OK, "t.toml").unwrap();
        let code = f.to_rust();
        assert!(code.contains(&format!("f32::from_bits(0x{:08x})", 0.875f32.to_bits())));
        assert_eq!(code.matches("firmware_sim::device::Frame {").count(), 5);
    }
}
