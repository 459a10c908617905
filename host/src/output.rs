//! Machine-readable output: the patch table of the design contract, as CSV and as JSON.
//!
//! The patch CSV header is fixed:
//! `patch,face,cx,cy,cz,nx,ny,nz,area,rho_r,rho_g,rho_b,e_r,e_g,e_b,b_r,b_g,b_b`. Numbers are printed with Rust's
//! shortest round-trip formatting, so an f64 read back from the CSV is the f64 that was written. The JSON form
//! ([`patch_json`]) carries the same columns per patch plus the polygon's vertices.

use std::io::{self, Write};

use crate::patch::Patch;
use crate::rgb::Rgb;

/// Header of the patch table CSV.
pub const PATCH_CSV_HEADER: &str =
    "patch,face,cx,cy,cz,nx,ny,nz,area,rho_r,rho_g,rho_b,e_r,e_g,e_b,b_r,b_g,b_b";

/// Writes the patch table CSV: one row per patch with its geometry, reflectance `rho`, emission `e` and
/// radiosity `b`.
///
/// # Errors
/// Any error of `out`.
///
/// # Panics
/// If `rho`, `e` or `b` is shorter than `patches`.
pub fn write_patch_csv(
    out: &mut impl Write,
    patches: &[Patch],
    rho: &[Rgb],
    e: &[Rgb],
    b: &[Rgb],
) -> io::Result<()> {
    writeln!(out, "{PATCH_CSV_HEADER}")?;
    for (k, p) in patches.iter().enumerate() {
        let (c, n) = (p.centroid, p.normal);
        write!(out, "{k},{},{},{},{},{},{},{},{}", p.face, c.x, c.y, c.z, n.x, n.y, n.z, p.area)?;
        for v in [rho[k], e[k], b[k]] {
            write!(out, ",{},{},{}", v[0], v[1], v[2])?;
        }
        writeln!(out)?;
    }
    Ok(())
}

/// The patch table as JSON: one object per patch with the CSV's columns (`patch`, `face`, `centroid`,
/// `normal`, `area`, `rho`, `e`, `b`; vectors and colours as `[x, y, z]`) and the polygon's `vertices`
/// (counter-clockwise seen from the side the normal points to).
///
/// # Panics
/// If `rho`, `e` or `b` is shorter than `patches`.
#[must_use]
pub fn patch_json(patches: &[Patch], rho: &[Rgb], e: &[Rgb], b: &[Rgb]) -> serde_json::Value {
    let rows: Vec<serde_json::Value> = patches
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let vertices: Vec<[f64; 3]> = p.vertices.iter().map(|v| v.to_array()).collect();
            serde_json::json!({
                "patch": k,
                "face": p.face,
                "centroid": p.centroid.to_array(),
                "normal": p.normal.to_array(),
                "area": p.area,
                "vertices": vertices,
                "rho": rho[k],
                "e": e[k],
                "b": b[k],
            })
        })
        .collect();
    serde_json::Value::Array(rows)
}
