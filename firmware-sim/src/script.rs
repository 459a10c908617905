//! Relight scripts: the TOML format, its parser and validation, and the Rust code the firmware compiles in.
//!
//! # Format (`scenes/*.relight.toml`)
//! ```toml
//! [[script]]
//! name = "lights-on"            # letters, digits, '-', '_'; unique in the file
//! description = "..."           # optional
//! tolerance = 1e-3              # convergence tolerance, power units (unshot |r|+|g|+|b| of a patch)
//! budget = 400                  # default per-frame budget in work units (optional if every frame has one)
//! boot_budget = 1000000         # optional (default 10_000_000): units the boot solve may spend
//! initial = [[0.0, 0.0, 0.0]]   # intensity (RGB) of every light group, in table order, solved at boot
//!
//! [[script.frame]]
//! intensity = [[1.0, 1.0, 1.0]] # optional: absolute intensities from this frame on (default: unchanged)
//! budget = 400                  # optional: overrides the script's budget
//! repeat = 10                   # optional (default 1): this frame this many times
//! ramp = false                  # optional: with `repeat = N`, step linearly from the previous intensity
//!                               # to `intensity` over the N frames (frame k of N at prev + (target - prev) k / N)
//! ```
//! A light group keeps its intensity until a frame names a new one; the device calls `set_light` only for
//! groups whose intensity changed. Intensities must be finite and non-negative; budgets at least 1.
//! The number of intensities per entry must equal the table's light-group count ([`ScriptFile::check_table`]).

use std::fmt::{self, Write as _};

use serde::Deserialize;

use crate::device::{Frame, Script};

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
    initial: Vec<[f64; 3]>,
    #[serde(default)]
    frame: Vec<TomlFrame>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TomlFrame {
    intensity: Option<Vec<[f64; 3]>>,
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
    /// Intensity of every light group.
    pub intensity: Vec<[f32; 3]>,
}

/// A parsed and expanded script (owned); [`OwnedScript::with_view`] lends it as a device [`Script`].
#[derive(Clone, Debug, PartialEq)]
pub struct OwnedScript {
    /// Name.
    pub name: String,
    /// Description.
    pub description: String,
    /// Convergence tolerance (power units).
    pub tolerance: f32,
    /// Boot budget (work units).
    pub boot_budget: u32,
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

fn intensities(v: &[[f64; 3]], at: &dyn Fn() -> String) -> Result<Vec<[f32; 3]>, ScriptError> {
    let mut out = Vec::with_capacity(v.len());
    for (g, rgb) in v.iter().enumerate() {
        for (c, x) in rgb.iter().enumerate() {
            if !x.is_finite() || *x < 0.0 || *x > f64::from(f32::MAX) {
                return Err(ScriptError(format!(
                    "{}: intensity of light group {g}, channel {c}: {x} is not a finite non-negative number",
                    at()
                )));
            }
        }
        out.push(rgb.map(|x| x as f32));
    }
    if out.is_empty() {
        return Err(ScriptError(format!("{}: no light-group intensities", at())));
    }
    Ok(out)
}

impl ScriptFile {
    /// Parses and validates a script file's text; `origin` (a path) names it in errors.
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
            let initial = intensities(&s.initial, &|| format!("{here}: initial"))?;
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
                let target = match &f.intensity {
                    Some(v) => intensities(v, &at)?,
                    None if f.ramp => {
                        return Err(ScriptError(format!("{}: ramp needs an intensity to ramp to", at())));
                    }
                    None => current.clone(),
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

    /// Checks that every script gives one intensity per light group of a table with `groups` light groups.
    ///
    /// # Errors
    /// A [`ScriptError`] naming the first script that does not.
    pub fn check_table(&self, groups: u32) -> Result<(), ScriptError> {
        for s in &self.scripts {
            if s.initial.len() != groups as usize {
                return Err(ScriptError(format!(
                    "script \"{}\": {} light-group intensities, the table has {groups} light groups",
                    s.name,
                    s.initial.len()
                )));
            }
        }
        Ok(())
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
        assert!(f.check_table(1).is_ok());
        assert!(f.check_table(2).unwrap_err().0.contains("the table has 2 light groups"));
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
