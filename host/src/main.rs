//! The `radiosity` command-line tool: bake scenes into tables, solve them exactly, and check the device.

use std::io::{self, BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use radiosity_host::formfactor::FormFactorOptions;
use radiosity_host::output::{write_patch_csv, Format};
use radiosity_host::pipeline::{prepare, PrepareOptions};
use radiosity_host::reference::{transfer_vectors, LightGroupEmission, Method, RadiositySystem};

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
    /// Solve the scene exactly in f64 (dense LU up to 4096 patches, Gauss-Seidel above) and print the patch
    /// table: `patch,face,cx,cy,cz,nx,ny,nz,area,rho_r,rho_g,rho_b,e_r,e_g,e_b,b_r,b_g,b_b`.
    Solve {
        #[command(flatten)]
        scene: SceneArgs,
        /// Output format (`text` prints a summary per light group; `csv` the patch table; `json` both).
        #[arg(long, value_enum, default_value_t = Format::Csv)]
        format: Format,
    },
    /// Bake the scene, run the device solver on the table (f32 and fixed point, a budget per frame, optional
    /// relighting) and compare every frame with the exact f64 answer; print the error decomposition.
    Check {
        #[command(flatten)]
        scene: SceneArgs,
        #[command(flatten)]
        check: radiosity_host::check::CheckArgs,
        /// Output format (`text` or `json`).
        #[arg(long, value_enum, default_value_t = Format::Text)]
        format: Format,
    },
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
                    for i in 0..p.form_factors.n {
                        for (j, f) in p.form_factors.row(i) {
                            writeln!(out, "{i},{j},{f}")?;
                        }
                    }
                }
                Format::Json => {
                    let rows: Vec<Vec<(usize, f64)>> =
                        (0..p.form_factors.n).map(|i| p.form_factors.row(i).collect()).collect();
                    let s = &p.stats;
                    let doc = serde_json::json!({
                        "patches": s.patches,
                        "nonzeros": s.nonzeros,
                        "row_sum_min": s.row_sum_min,
                        "row_sum_max": s.row_sum_max,
                        "reciprocity_error_max": s.reciprocity_error_max,
                        "rays_cast": s.rays_cast,
                        "rays_per_second": s.rays_per_second,
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
                    writeln!(out, "time                  {:.3} s", s.elapsed.as_secs_f64())?;
                }
            }
        }
        Command::Solve { scene, format } => {
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            let l = &p.lighting;
            let system = RadiositySystem::new(&l.rho, &p.form_factors)?;
            let method = Method::for_size(p.patches.len());
            let lights = LightGroupEmission {
                static_emission: &l.static_emission,
                unit_emission: &l.unit_emission,
                group: &l.group,
                group_count: l.dynamic_groups.len(),
            };
            let tv = transfer_vectors(system, &lights, &method)?;
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
        Command::Check { scene, check, format } => {
            let report =
                radiosity_host::check::check_scene(&scene.scene, &scene.prepare_options(), &check.options())?;
            match format {
                Format::Json => writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?,
                _ => write!(out, "{report}")?,
            }
        }
    }
    out.flush()?;
    Ok(())
}
