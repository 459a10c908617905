//! The continuous reference's result: per-face radiosity with its standard error, as text, CSV and JSON.

use std::fmt;
use std::io::{self, Write};
use std::time::Duration;

use serde::Serialize;

use crate::rgb::Rgb;

/// Header of the per-face CSV ([`ContinuousReference::write_csv`]).
pub const FACE_CSV_HEADER: &str =
    "face,area,rho_r,rho_g,rho_b,e_r,e_g,e_b,b_r,b_g,b_b,se_r,se_g,se_b,samples,source";

/// The largest relative standard error over the channels with `b > 0` (0 if none).
pub(super) fn relative_error(b: Rgb, se: Rgb) -> f64 {
    (0..3).filter(|&c| b[c] > 0.0).map(|c| se[c] / b[c]).fold(0.0, f64::max)
}

/// The estimate for one face of the scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaceReference {
    /// Index of the face in load order (OBJ order for an OBJ file).
    pub face: usize,
    /// Where the face is in its file ([`Face::place`](crate::scene::Face::place)): `line 12` for an OBJ face,
    /// its node, mesh, primitive and triangles for a glTF face.
    pub source: String,
    /// Area (scene units squared).
    pub area: f64,
    /// Reflectance.
    pub rho: Rgb,
    /// Emission at the scene's default intensities (W/m^2).
    pub emission: Rgb,
    /// Area-averaged radiosity (W/m^2).
    pub radiosity: Rgb,
    /// Standard error of `radiosity` per channel (conservative, see the module docs of [`super`]).
    pub standard_error: Rgb,
    /// The largest relative standard error over the channels with nonzero radiosity.
    pub relative_standard_error: f64,
    /// Paths traced from the face.
    pub samples: u64,
}

impl FaceReference {
    /// The estimate of face `face` (at `source` in its file, area `area`), with its relative error computed.
    #[allow(clippy::too_many_arguments)]
    #[must_use]
    pub fn new(
        face: usize,
        source: String,
        area: f64,
        rho: Rgb,
        emission: Rgb,
        radiosity: Rgb,
        standard_error: Rgb,
        samples: u64,
    ) -> Self {
        let relative_standard_error = relative_error(radiosity, standard_error);
        FaceReference {
            face,
            source,
            area,
            rho,
            emission,
            radiosity,
            standard_error,
            relative_standard_error,
            samples,
        }
    }
}

/// The continuous reference of a scene: one [`FaceReference`] per face, in load order.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ContinuousReference {
    /// Per face, in load order.
    pub faces: Vec<FaceReference>,
    /// The relative standard error aimed at, if any (`None`: a fixed number of paths per face).
    pub target: Option<f64>,
    /// Whether every face reached the target (`true` without a target).
    pub target_met: bool,
    /// Seed of the random numbers.
    pub seed: u64,
    /// Rounds of batches run.
    pub rounds: usize,
    /// Paths traced, all faces.
    pub paths: u64,
    /// Rays cast (shadow and bounce rays).
    pub rays: u64,
    /// Wall time (seconds), scene setup included.
    pub seconds: f64,
}

impl ContinuousReference {
    /// Collects the per-face estimates and the run's statistics.
    #[must_use]
    pub fn new(
        faces: Vec<FaceReference>,
        target: Option<f64>,
        seed: u64,
        rounds: usize,
        rays: u64,
        elapsed: Duration,
    ) -> Self {
        let target_met = target.is_none_or(|t| faces.iter().all(|f| f.relative_standard_error <= t));
        let paths = faces.iter().map(|f| f.samples).sum();
        ContinuousReference {
            faces,
            target,
            target_met,
            seed,
            rounds,
            paths,
            rays,
            seconds: elapsed.as_secs_f64(),
        }
    }

    /// The largest relative standard error over the faces.
    #[must_use]
    pub fn worst_relative_error(&self) -> f64 {
        self.faces.iter().map(|f| f.relative_standard_error).fold(0.0, f64::max)
    }

    /// Writes the per-face CSV: [`FACE_CSV_HEADER`], then one row per face in shortest round-trip formatting;
    /// the last column, `source`, is quoted as RFC 4180 says when it holds a comma or a quote (a glTF face's
    /// place does).
    ///
    /// # Errors
    /// Any error of `out`.
    pub fn write_csv(&self, out: &mut impl Write) -> io::Result<()> {
        writeln!(out, "{FACE_CSV_HEADER}")?;
        for f in &self.faces {
            write!(out, "{},{}", f.face, f.area)?;
            for v in [f.rho, f.emission, f.radiosity, f.standard_error] {
                write!(out, ",{},{},{}", v.x, v.y, v.z)?;
            }
            writeln!(out, ",{},{}", f.samples, crate::text::csv_field(&f.source))?;
        }
        Ok(())
    }

    /// A one-line summary: paths, rays, time and the worst relative standard error.
    #[must_use]
    pub fn summary(&self) -> String {
        let target = match self.target {
            Some(t) if self.target_met => format!(", target {t:.2e} met"),
            Some(t) => format!(", target {t:.2e} NOT met (cap reached)"),
            None => String::new(),
        };
        format!(
            "{}, {} paths, {} rays in {:.2} s ({}); worst relative standard error {:.2e}{target}",
            crate::text::counted(self.faces.len(), "face", "faces"),
            self.paths,
            self.rays,
            self.seconds,
            crate::text::counted(self.rounds, "round", "rounds"),
            self.worst_relative_error()
        )
    }
}

impl fmt::Display for ContinuousReference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "continuous reference (path traced, seed {}): {}", self.seed, self.summary())?;
        writeln!(
            f,
            "{:>5} {:>11} {:>11} {:>11} {:>11} {:>9} {:>9}  source",
            "face", "area", "B r", "B g", "B b", "rel SE", "paths"
        )?;
        for r in &self.faces {
            writeln!(
                f,
                "{:>5} {:>11.4e} {:>11.5e} {:>11.5e} {:>11.5e} {:>9.2e} {:>9}  {}",
                r.face,
                r.area,
                r.radiosity.x,
                r.radiosity.y,
                r.radiosity.z,
                r.relative_standard_error,
                r.samples,
                r.source
            )?;
        }
        Ok(())
    }
}
