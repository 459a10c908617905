//! The `radiosity` command-line tool: bake scenes into tables, solve them exactly, and check the device.

use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use radiosity_host::bake::{bake, codec_for_bits, BakeInput, BakeOptions};
use radiosity_host::formfactor::FormFactorOptions;
use radiosity_host::inspect::inspect_file;
use radiosity_host::output::{write_patch_csv, Format};
use radiosity_host::picture::{camera::Camera, write_png};
use radiosity_host::pipeline::Prepared;
use radiosity_host::pipeline::{prepare, PrepareOptions};
use radiosity_host::reference::{exact_transfer, Method};
use radiosity_host::relight;
use radiosity_host::view;

/// Precomputed diffuse lighting for small devices: scenes in, quantized form-factor tables out, every answer
/// checked against an exact f64 solve.
#[derive(Parser)]
#[command(name = "radiosity", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the form factors F_ij of a scene (the fraction of power leaving patch i that reaches patch j).
    ///
    /// `--format csv` prints `i,j,f_ij` for every nonzero pair in f64; `text` prints statistics.
    Formfactors {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output format.
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Bake a scene into a table for the device: form factors, sparsify, fold static lights, quantize, write.
    ///
    /// Prints a summary (sizes, energy dropped, error of sparsify + quantize against the f64 solve) and writes
    /// TABLE plus, beside it, TABLE.capacities.json (the counts and buffer sizes a firmware build needs; the
    /// firmware's build script derives the same sizes from the table itself with core's `BufferSizes::of`).
    Bake {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output table file (.rft).
        #[arg(short, long, value_name = "TABLE")]
        output: PathBuf,
        /// Bits per form-factor code: 16 (small float, relative error < 2^-12) or 8 (< 2^-5).
        #[arg(long, default_value_t = 16)]
        bits: u32,
        /// Sparsification threshold: the largest fraction of a row's (and a receiver's) energy that may be
        /// dropped.
        #[arg(long, default_value_t = radiosity_host::bake::DEFAULT_THRESHOLD)]
        threshold: f64,
        /// Also store the transfer basis (the response of every patch to every dynamic light group), so the
        /// device can relight as B = B_static + sum_g I_g T_g in one pass; the summary reports its bytes and
        /// relight error.
        #[arg(long)]
        transfer: bool,
        /// Output format of the summary.
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Validate a table with the device's own parser and print its header and statistics.
    Inspect {
        /// The table file (.rft).
        table: PathBuf,
        /// Output format.
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Run the main job on the bundled Cornell box: bake it at its default (adaptive) mesh, validate the table,
    /// render it (view, light-map atlas, device error map, mesh histogram), then bake a table within 400 patches
    /// for a Cortex-M4 and run the "lights-on" relight script on it, on the host and under QEMU, printing every
    /// frame's error against f64 next to the instructions it took. Everything lands in the output folder.
    Demo {
        /// Folder for the outputs.
        #[arg(long, default_value = "out")]
        out: PathBuf,
    },
    /// Solve the scene exactly in f64 (dense LU up to 4096 patches, Gauss-Seidel above) and print the patch
    /// table: `patch,face,cx,cy,cz,nx,ny,nz,area,rho_r,rho_g,rho_b,e_r,e_g,e_b,b_r,b_g,b_b`.
    Solve {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output format (`text` prints a summary per light group; `csv` the patch table; `json` both).
        #[arg(long, value_enum, default_value_t = Format::Csv)]
        format: Format,
    },
    /// Solve the scene in f64 (as `solve`) and render a view of it to a PNG (smoothly shaded, or one colour per
    /// patch to show the mesh). Prints the output path.
    Render {
        #[command(flatten)]
        scene: SceneArgs,
        /// Camera as "px,py,pz;tx,ty,tz;ux,uy,uz;fov_degrees" (position; target; up; vertical field of view).
        /// Default: the published Cornell camera for scenes named cornell-box*, else a view of the bounding box.
        #[arg(long, allow_hyphen_values = true)]
        camera: Option<String>,
        /// Image width in pixels.
        #[arg(long, default_value_t = 512)]
        width: u32,
        /// Image height in pixels.
        #[arg(long, default_value_t = 512)]
        height: u32,
        /// What the picture shows.
        #[arg(long, value_enum, default_value_t = RenderModeArg::Shaded)]
        mode: RenderModeArg,
        /// Table for `--mode error` (baked from SCENE with the same meshing options; default: bake one).
        #[arg(long, value_name = "TABLE")]
        table: Option<PathBuf>,
        /// Output PNG file.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Run relight scripts on a table the way the device runs them and print every frame's error against the
    /// exact f64 answer for that frame's light intensities.
    ///
    /// The device loop (the code the firmware links) runs on the host in f32 and Q32.32 fixed point; with
    /// `--qemu` the Cortex-M4 firmware is also built with the same table and scripts and run under
    /// qemu-system-arm (mps2-an386, -icount shift=0), adding the instructions each frame took, flash and RAM use,
    /// and a bit-for-bit comparison of every frame with the host run.
    Relight {
        #[command(flatten)]
        scene: SceneArgs,
        /// The table baked from SCENE with the same meshing options (default: bake one at default settings).
        #[arg(long, value_name = "TABLE")]
        table: Option<PathBuf>,
        /// Relight scripts (TOML, format in firmware-sim/src/script.rs; default: SCENE's stem + .relight.toml).
        #[arg(long, value_name = "FILE")]
        scripts: Option<PathBuf>,
        /// Only the script of this name.
        #[arg(long, value_name = "NAME")]
        script: Option<String>,
        /// Also build the Cortex-M4 firmware and run it under QEMU (needs `make deps`).
        #[arg(long)]
        qemu: bool,
        /// Render the f32 device answer of every frame of the first selected script to DIR/SCRIPT-NNNN.png.
        #[arg(long, value_name = "DIR")]
        frames: Option<PathBuf>,
        /// Size of the frame pictures (pixels, square).
        #[arg(long, default_value_t = 256)]
        frame_size: u32,
        /// Write the per-frame rows as CSV to FILE.
        #[arg(long, value_name = "FILE")]
        csv: Option<PathBuf>,
        /// Plot error against cumulative work units per script to STEM.svg and STEM.png.
        #[arg(long, value_name = "STEM")]
        plot: Option<PathBuf>,
        /// Output format (`text`: a table per frame; `csv`: the per-frame rows; `json`: everything).
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Solve the scene in f64 (as `solve`) and write its light-map atlas: STEM.hdr (linear W/m^2), STEM.png (tone
    /// mapped, sRGB) and STEM.json (the face -> atlas rectangle map, every face). Prints the paths.
    Lightmap {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output path without extension.
        #[arg(short, long, value_name = "STEM")]
        output: PathBuf,
    },
    /// Bake the scene, run the device solver on the table (f32 and fixed point, a budget per frame, optional
    /// relighting) and compare every frame with the exact f64 answer; print the error decomposition.
    ///
    /// `radiosity check TABLE.rft --scene SCENE.obj` checks an existing table instead: it must have been baked
    /// from SCENE with the same meshing options (else a clear error naming the first difference).
    Check {
        /// The scene's OBJ file, or a table (.rft) together with `--scene`.
        #[command(flatten)]
        scene: SceneArgs,
        /// With a table as the first argument: the scene it was baked from.
        #[arg(long = "scene", id = "table_scene", value_name = "SCENE")]
        table_scene: Option<PathBuf>,
        #[command(flatten)]
        check: radiosity_host::check::CheckArgs,
        /// Also plot the error decomposition as stacked bars (one per arithmetic path) to STEM.svg and STEM.png.
        #[arg(long, value_name = "STEM")]
        plot: Option<PathBuf>,
        /// Output format (`text` or `json`).
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Quantization regression: recompute every shipped scene's error components (16- and 8-bit codecs) and
    /// compare them with the checked-in baseline (fails when one exceeds baseline + k * noise);
    /// `--update` re-measures and rewrites the baseline, printing old and new values side by side.
    Regress {
        #[command(flatten)]
        regress: radiosity_host::regress::RegressArgs,
        /// Output format (`text` or `json`).
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
    /// Measure speed against error for every relighting method (core shooting with and without overshooting,
    /// Gauss-Seidel, Jacobi, warm and cold relighting, the precomputed transfer basis, f64 dense LU and
    /// Gauss-Seidel), the roofline and the bake throughput; write REPORT.md,
    /// CSV files and plots into the output folder. Run it from a release build.
    Bench(radiosity_host::bench::BenchArgs),
}

/// `render --mode`.
#[derive(Clone, Copy, clap::ValueEnum)]
enum RenderModeArg {
    /// Smoothly shaded radiosity, tone mapped.
    Shaded,
    /// One colour per patch (the mesh).
    Patches,
    /// The device's converged f32 answer on a table (`--table`, or one baked at default settings), false-coloured
    /// by its relative error against the exact f64 answer, with a legend.
    Error,
}

/// Options shared by the commands that read a scene.
#[derive(Args)]
struct SceneArgs {
    /// The scene's OBJ file (its MTL files and an optional NAME.toml beside it are read too).
    scene: PathBuf,
    /// One patch per OBJ face: patch k is face k, so results can be checked against hand computations.
    #[arg(long)]
    no_subdivide: bool,
    /// Longest patch edge after uniform subdivision, in scene units (default: the scene's TOML, or 1/8 of its
    /// extent).
    #[arg(long, value_name = "LENGTH")]
    max_patch_edge: Option<f64>,
    /// Most patches the mesh may have (default: the scene's TOML, or 4096).
    #[arg(long, value_name = "N")]
    max_patches: Option<usize>,
    /// Sample points on each patch for the form-factor integral.
    #[arg(long, value_name = "N", default_value_t = FormFactorOptions::default().samples_per_patch)]
    samples: usize,
    /// Occlusion rays per patch pair.
    #[arg(long, value_name = "N", default_value_t = FormFactorOptions::default().rays_per_pair)]
    rays: usize,
    /// Seed of the form-factor sampling; equal seeds give identical results on any thread count.
    #[arg(long, default_value_t = FormFactorOptions::default().seed)]
    seed: u64,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// No progress bar or stage summaries on stderr.
    #[arg(long, short)]
    quiet: bool,
}

impl SceneArgs {
    fn prepare_options(&self) -> PrepareOptions {
        PrepareOptions {
            no_subdivide: self.no_subdivide,
            max_patch_edge: self.max_patch_edge,
            max_patches: self.max_patches,
            form_factors: FormFactorOptions {
                samples_per_patch: self.samples,
                rays_per_pair: self.rays,
                seed: self.seed,
                progress: !self.quiet,
                threads: self.threads,
                ..FormFactorOptions::default()
            },
            verbose: !self.quiet,
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            let mut source = e.source();
            while let Some(s) = source {
                eprintln!("  caused by: {s}");
                source = s.source();
            }
            ExitCode::FAILURE
        }
    }
}

type BoxError = Box<dyn std::error::Error>;

fn run(cli: Cli) -> Result<(), BoxError> {
    let stdout = io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    match cli.command {
        Command::Formfactors { scene, format } => {
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            match format {
                Format::Csv => {
                    writeln!(out, "i,j,f_ij")?;
                    for i in 0..p.form_factors.n() {
                        for (j, f) in p.form_factors.row(i) {
                            writeln!(out, "{i},{j},{f}")?;
                        }
                    }
                }
                Format::Json => {
                    let rows: Vec<Vec<(usize, f64)>> =
                        (0..p.form_factors.n()).map(|i| p.form_factors.row(i).collect()).collect();
                    let s = &p.stats;
                    let doc = serde_json::json!({
                        "patches": s.patches,
                        "nonzeros": s.nonzeros,
                        "row_sum_min": s.row_sum_min,
                        "row_sum_max": s.row_sum_max,
                        "reciprocity_error_max": s.reciprocity_error_max,
                        "rays_cast": s.rays_cast,
                        "rays_per_second": s.rays_per_second,
                        "kernel_evaluations": s.kernel_evaluations,
                        "kernel_seconds": s.kernel_time.as_secs_f64(),
                        "visibility_seconds": s.visibility_time.as_secs_f64(),
                        "seconds": s.elapsed.as_secs_f64(),
                        "rows": rows,
                    });
                    serde_json::to_writer_pretty(&mut out, &doc)?;
                    writeln!(out)?;
                }
                Format::Text => {
                    let s = &p.stats;
                    writeln!(out, "patches               {}", s.patches)?;
                    writeln!(out, "nonzeros              {}", s.nonzeros)?;
                    writeln!(out, "row sums              {:.6} .. {:.6}", s.row_sum_min, s.row_sum_max)?;
                    writeln!(out, "reciprocity error max {:.3e}", s.reciprocity_error_max)?;
                    writeln!(out, "rays cast             {}", s.rays_cast)?;
                    writeln!(out, "rays per second       {:.3e}", s.rays_per_second)?;
                    writeln!(out, "kernel evaluations    {}", s.kernel_evaluations)?;
                    writeln!(
                        out,
                        "phases                kernels {:.3} s, visibility {:.3} s",
                        s.kernel_time.as_secs_f64(),
                        s.visibility_time.as_secs_f64()
                    )?;
                    writeln!(out, "time                  {:.3} s", s.elapsed.as_secs_f64())?;
                }
            }
        }
        Command::Bake { scene, output, bits, threshold, transfer, format } => {
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            bake_to_files(&p, &output, bits, threshold, transfer, format, &mut out)?;
        }
        Command::Inspect { table, format } => {
            let report = inspect_file(&table)?;
            match format {
                Format::Json => {
                    serde_json::to_writer_pretty(&mut out, &report)?;
                    writeln!(out)?;
                }
                Format::Text | Format::Csv => writeln!(out, "{report}")?,
            }
        }
        Command::Demo { out: dir } => demo(&dir, &mut out)?,
        Command::Bench(args) => {
            radiosity_host::bench::run(&args.options())?;
            writeln!(out, "wrote {}", args.out.join("REPORT.md").display())?;
        }
        Command::Solve { scene, format } => {
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            let l = &p.lighting;
            let tv = exact_transfer(l, &p.form_factors, &Method::for_size(p.patches.len()))?;
            let b = tv.relight(&l.default_intensity)?;
            let e = l.default_emission();
            match format {
                Format::Csv => write_patch_csv(&mut out, &p.patches, &l.rho, &e, &b)?,
                Format::Text | Format::Json => {
                    let area: f64 = p.patches.iter().map(|q| q.area).sum();
                    let mean = |v: &[[f64; 3]]| -> [f64; 3] {
                        let mut m = [0.0; 3];
                        for (q, x) in p.patches.iter().zip(v) {
                            for c in 0..3 {
                                m[c] += q.area * x[c] / area;
                            }
                        }
                        m
                    };
                    let groups: Vec<serde_json::Value> = l
                        .dynamic_groups
                        .iter()
                        .zip(&tv.t)
                        .map(|(&g, t)| {
                            serde_json::json!({
                                "group": p.scene.light_groups[g].name,
                                "mean_unit_response": mean(t),
                            })
                        })
                        .collect();
                    let doc = serde_json::json!({
                        "patches": p.patches.len(),
                        "relative_residual": tv.residual,
                        "mean_radiosity": mean(&b),
                        "mean_static_radiosity": mean(&tv.b_static),
                        "dynamic_groups": groups,
                    });
                    if format == Format::Json {
                        let mut full = doc;
                        full["b"] = serde_json::json!(b);
                        serde_json::to_writer_pretty(&mut out, &full)?;
                        writeln!(out)?;
                    } else {
                        writeln!(out, "{}", serde_json::to_string_pretty(&doc)?)?;
                    }
                }
            }
        }
        Command::Render { scene, camera, width, height, mode, table, output } => {
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            let exact = view::solve_default(&p)?;
            let camera = camera.map(|c| Camera::parse(&c)).transpose()?;
            let (b, mode) = match mode {
                RenderModeArg::Shaded => (exact.clone(), view::RenderMode::Shaded),
                RenderModeArg::Patches => (exact.clone(), view::RenderMode::Patches),
                RenderModeArg::Error => {
                    let bytes = table_bytes(&p, table.as_deref())?;
                    let intensity: Vec<[f32; 3]> =
                        p.lighting.default_intensity.iter().map(|v| v.map(|x| x as f32)).collect();
                    let b = relight::device_answer(&bytes, &intensity)?;
                    (b, view::RenderMode::Error { reference: &exact })
                }
            };
            let image = view::render_scene(&p, &b, &view::RenderOptions { camera, width, height, mode })?;
            write_png(&output, &image)?;
            writeln!(out, "{}", output.display())?;
        }
        Command::Relight { scene, table, scripts, script, qemu, frames, frame_size, csv, plot, format } => {
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            let scripts = scripts.unwrap_or_else(|| scene.scene.with_extension("relight.toml"));
            let (table_path, _temp) = match table {
                Some(t) => (t, None),
                None => {
                    let bytes = table_bytes(&p, None)?;
                    let path =
                        std::env::temp_dir().join(format!("radiosity-relight-{}.rft", std::process::id()));
                    std::fs::write(&path, &bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
                    (path.clone(), Some(TempFile(path)))
                }
            };
            let bytes =
                std::fs::read(&table_path).map_err(|e| format!("reading {}: {e}", table_path.display()))?;
            let options =
                relight::RelightOptions { only: script, qemu, ..relight::RelightOptions::default() };
            let report = relight::relight(&p, &bytes, &table_path, &scripts, &options)?;
            write_relight_outputs(
                &p,
                &report,
                frames.as_deref(),
                frame_size,
                csv.as_deref(),
                plot.as_deref(),
                &mut out,
            )?;
            match format {
                Format::Text => write!(out, "{report}")?,
                Format::Csv => write!(out, "{}", report.to_csv())?,
                Format::Json => {
                    serde_json::to_writer_pretty(&mut out, &report)?;
                    writeln!(out)?;
                }
            }
        }
        Command::Lightmap { scene, output } => {
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            for path in view::write_light_map(&p, &view::solve_default(&p)?, &output)? {
                writeln!(out, "{}", path.display())?;
            }
        }
        Command::Check { scene, table_scene, check, plot, format } => {
            if table_scene.is_none() && scene.scene.extension().is_some_and(|e| e == "rft") {
                return Err(format!(
                    "{} is a table: give the scene it was baked from with --scene SCENE.obj",
                    scene.scene.display()
                )
                .into());
            }
            let report = match table_scene {
                Some(obj) => radiosity_host::check::check_table_file(
                    &scene.scene,
                    &obj,
                    &scene.prepare_options(),
                    &check.options(),
                )?,
                None => radiosity_host::check::check_scene(
                    &scene.scene,
                    &scene.prepare_options(),
                    &check.options(),
                )?,
            };
            match format {
                Format::Json => writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?,
                _ => write!(out, "{report}")?,
            }
            if let Some(stem) = plot {
                let title =
                    format!("Error decomposition: {} ({} patches)", scene.scene.display(), report.patches);
                let (svg, png) = report.decomposition_plot(&title).write(&stem, 800, 500)?;
                writeln!(out, "{}\n{}", svg.display(), png.display())?;
            }
        }
        Command::Regress { regress, format } => {
            let report = radiosity_host::regress::run(&regress)?;
            match format {
                Format::Json => writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?,
                _ => write!(out, "{report}")?,
            }
            if !report.passed() {
                out.flush()?;
                return Err(format!(
                    "regression: {} values over their limits, {} problems",
                    report.failures().len(),
                    report.problems.len()
                )
                .into());
            }
        }
    }
    out.flush()?;
    Ok(())
}

/// Bakes `p` into `output` (plus the capacities files beside it) and prints the summary.
fn bake_to_files(
    p: &Prepared,
    output: &std::path::Path,
    bits: u32,
    threshold: f64,
    transfer: bool,
    format: Format,
    out: &mut impl Write,
) -> Result<(), BoxError> {
    let options = BakeOptions { threshold, codec: codec_for_bits(bits)?, transfer, ..BakeOptions::default() };
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &options)?;
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
    }
    let write = |path: PathBuf, bytes: &[u8]| -> Result<PathBuf, BoxError> {
        std::fs::write(&path, bytes).map_err(|e| format!("writing {}: {e}", path.display()))?;
        Ok(path)
    };
    let table = write(output.to_path_buf(), &baked.table)?;
    let json = write(
        with_suffix(output, ".capacities.json"),
        serde_json::to_string_pretty(&baked.capacities)?.as_bytes(),
    )?;
    match format {
        Format::Json => {
            serde_json::to_writer_pretty(&mut *out, &baked.report)?;
            writeln!(out)?;
        }
        Format::Text | Format::Csv => {
            writeln!(out, "{}", baked.report)?;
            writeln!(out, "wrote {}, {}", table.display(), json.display())?;
        }
    }
    Ok(())
}

/// The table's bytes: read from `path`, or baked from `p` at default settings.
fn table_bytes(p: &Prepared, path: Option<&std::path::Path>) -> Result<Vec<u8>, BoxError> {
    match path {
        Some(path) => Ok(std::fs::read(path).map_err(|e| format!("reading {}: {e}", path.display()))?),
        None => {
            let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
            Ok(bake(&input, &BakeOptions::default())?.table)
        }
    }
}

/// A temporary file removed when dropped.
struct TempFile(PathBuf);

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Writes the optional outputs of `relight` (frame pictures, CSV, plot) and prints their paths.
fn write_relight_outputs(
    p: &Prepared,
    report: &relight::RelightReport,
    frames: Option<&std::path::Path>,
    frame_size: u32,
    csv: Option<&std::path::Path>,
    plot: Option<&std::path::Path>,
    out: &mut impl Write,
) -> Result<(), BoxError> {
    if let Some(dir) = frames {
        let paths = relight::write_frames(p, report, dir, frame_size, frame_size)?;
        if let (Some(first), Some(last)) = (paths.first(), paths.last()) {
            writeln!(out, "frames of {}: {} .. {}", report.first_script, first.display(), last.display())?;
        }
    }
    if let Some(path) = csv {
        std::fs::write(path, report.to_csv()).map_err(|e| format!("writing {}: {e}", path.display()))?;
        writeln!(out, "{}", path.display())?;
    }
    if let Some(stem) = plot {
        let chart = radiosity_host::picture::plot::Plot::ErrorWork {
            title: "Relight scripts: device error against the exact f64 answer".into(),
            x_label: "cumulative work units (light changes + shooting)".into(),
            y_label: "relative L2 error of B".into(),
            series: report.error_series(),
        };
        let (svg, png) = chart.write(stem, 900, 600)?;
        writeln!(out, "{}\n{}", svg.display(), png.display())?;
    }
    Ok(())
}

/// `path` with `suffix` appended to its file name.
fn with_suffix(path: &std::path::Path, suffix: &str) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(suffix);
    path.with_file_name(name)
}

/// The bundled Cornell box, from the repository root or from beside the binary's crate.
fn cornell_box_path() -> PathBuf {
    let local = PathBuf::from("scenes/cornell-box.obj");
    if local.exists() {
        local
    } else {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box.obj")
    }
}

/// Patch budget of the demo's device table: with 16-bit codes its table (~0.27 MB) plus the firmware's code
/// fit the 512 KiB flash of the emulated Cortex-M4 board.
const DEVICE_PATCH_BUDGET: usize = 400;

/// The main job on the Cornell box: prepare, bake, validate the table with the device's parser.
fn demo(dir: &std::path::Path, out: &mut impl Write) -> Result<(), BoxError> {
    let scene = cornell_box_path();
    writeln!(out, "== Cornell box: {}", scene.display())?;
    let options = PrepareOptions {
        no_subdivide: false,
        max_patch_edge: None,
        max_patches: None,
        form_factors: FormFactorOptions::default(),
        verbose: true,
    };
    let p = prepare(&scene, &options)?;
    writeln!(out, "\n== bake (16-bit codes)")?;
    let table = dir.join("cornell-box.rft");
    bake_to_files(&p, &table, 16, radiosity_host::bake::DEFAULT_THRESHOLD, false, Format::Text, out)?;
    writeln!(out, "\n== inspect {} (validated by the device's own parser)", table.display())?;
    writeln!(out, "{}", inspect_file(&table)?)?;
    writeln!(out, "\n== pictures (exact f64 solve, published camera)")?;
    let b = view::solve_default(&p)?;
    let image = view::render_scene(
        &p,
        &b,
        &view::RenderOptions { camera: None, width: 512, height: 512, mode: view::RenderMode::Shaded },
    )?;
    let png = dir.join("cornell-box.png");
    write_png(&png, &image)?;
    writeln!(out, "{}", png.display())?;
    for path in view::write_light_map(&p, &b, &dir.join("cornell-box-lightmap"))? {
        writeln!(out, "{}", path.display())?;
    }
    let bytes = std::fs::read(&table).map_err(|e| format!("reading {}: {e}", table.display()))?;
    let intensity: Vec<[f32; 3]> = p.lighting.default_intensity.iter().map(|v| v.map(|x| x as f32)).collect();
    let device = relight::device_answer(&bytes, &intensity)?;
    let image = view::render_scene(
        &p,
        &device,
        &view::RenderOptions {
            camera: None,
            width: 512,
            height: 512,
            mode: view::RenderMode::Error { reference: &b },
        },
    )?;
    let error_png = dir.join("cornell-box-error.png");
    write_png(&error_png, &image)?;
    writeln!(out, "{} (device answer on the table, relative error against f64)", error_png.display())?;
    let areas: Vec<f64> = p.patches.iter().map(|q| q.area).collect();
    let histogram = radiosity_host::picture::plot::Plot::Histogram {
        title: format!("Cornell box mesh: {} patches", p.patches.len()),
        x_label: "patch area (scene units^2)".into(),
        values: areas,
        bins: 24,
    };
    let (svg, png) = histogram.write(&dir.join("cornell-box-mesh"), 800, 500)?;
    writeln!(out, "{}\n{}", svg.display(), png.display())?;

    // The default mesh (about 1,000 patches) gives a table of ~1.6 MB: the pictures' quality, not a Cortex-M4's
    // flash. The device gets its own bake of the same scene within a patch budget whose table plus firmware code
    // fit the 512 KiB of flash of the emulated board (mps2-an386).
    writeln!(
        out,
        "\n== device table: the same scene within {DEVICE_PATCH_BUDGET} patches, for a Cortex-M4 with 512 KiB \
         flash"
    )?;
    let device_options = PrepareOptions { max_patches: Some(DEVICE_PATCH_BUDGET), verbose: false, ..options };
    let p = prepare(&scene, &device_options)?;
    let table = dir.join("cornell-box-m4.rft");
    bake_to_files(&p, &table, 16, radiosity_host::bake::DEFAULT_THRESHOLD, false, Format::Text, out)?;
    let bytes = std::fs::read(&table).map_err(|e| format!("reading {}: {e}", table.display()))?;

    let scripts = scene.with_extension("relight.toml");
    let script = "lights-on";
    writeln!(
        out,
        "\n== relight script {script:?} ({}) on {}: device loop on the host (f32, fixed point) and the Cortex-M4 \
         firmware under QEMU",
        scripts.display(),
        table.display()
    )?;
    let options = relight::RelightOptions {
        only: Some(script.into()),
        qemu: true,
        ..relight::RelightOptions::default()
    };
    let report = match relight::relight(&p, &bytes, &table, &scripts, &options) {
        Ok(r) => r,
        Err(e @ relight::RelightError::Qemu { .. }) => {
            writeln!(out, "QEMU run skipped: {e}\n(the host simulator's numbers follow)")?;
            let options = relight::RelightOptions { qemu: false, ..options };
            relight::relight(&p, &bytes, &table, &scripts, &options)?
        }
        Err(e) => return Err(e.into()),
    };
    write!(out, "{report}")?;
    writeln!(out, "instructions: light change + shooting per frame, counted by SysTick under QEMU -icount (firmware-sim/COST.md)")?;
    write_relight_outputs(
        &p,
        &report,
        Some(&dir.join("frames")),
        256,
        Some(&dir.join("cornell-box-relight.csv")),
        Some(&dir.join("cornell-box-relight")),
        out,
    )?;
    Ok(())
}
