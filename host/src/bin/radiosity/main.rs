//! The `radiosity` command-line tool: bake scenes into tables, solve them exactly, and check the device.

use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Parser;
use radiosity_host::bake::{
    bake, bake_hierarchy, codec_for_bits, BakeInput, BakeOptions, DeviceFit, HierBakeSummary,
};
use radiosity_host::evaluate::{evaluate, BakeSummary, EvaluateOptions};
use radiosity_host::files;
use radiosity_host::formfactor::FormFactorOptions;
use radiosity_host::hierarchy::{
    solve_hierarchical, solve_hierarchical_noting, HierarchicalSolution, HierarchyOptions, Refinement,
    ANSWER_SAMPLES_PER_PATCH, ANSWER_SENDER_WEIGHT, DEFAULT_EPSILON, DEFAULT_MAX_LINKS,
};
use radiosity_host::inspect::inspect_file;
use radiosity_host::output::{patch_json, write_patch_csv};

mod args;
use args::{Cli, Command, Format, RenderModeArg, ReportFormat, SolveMethod};
use radiosity_host::montecarlo::ReferenceOptions;
use radiosity_host::picture::lightmap::LightMapOptions;
use radiosity_host::picture::{camera::Camera, write_png};
use radiosity_host::pipeline::Prepared;
use radiosity_host::pipeline::{prepare, PrepareOptions};
use radiosity_host::reference::{exact_transfer, Method};
use radiosity_host::relight;
use radiosity_host::rgb::Rgb;
use radiosity_host::scene::{Scene, SceneGltf};
use radiosity_host::text::counted;
use radiosity_host::view;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let message = e.to_string();
            eprintln!("error: {message}");
            // Many errors show their source in their own message as well: a cause already said is not repeated.
            let mut said = message;
            let mut source = e.source();
            while let Some(s) = source {
                let cause = s.to_string();
                if !said.contains(&cause) {
                    eprintln!("  caused by: {cause}");
                    said.push('\n');
                    said.push_str(&cause);
                }
                source = s.source();
            }
            ExitCode::FAILURE
        }
    }
}

type BoxError = Box<dyn std::error::Error>;

/// Checks the options every scene command shares against their limits ([`radiosity_host::limits`]), before any
/// work.
fn check_scene_args(scene: &args::SceneArgs) -> Result<(), BoxError> {
    use radiosity_host::limits::{check_count, MAX_PATCHES, MAX_RAYS, MAX_SAMPLES, MAX_THREADS};
    if let Some(n) = scene.max_patches {
        check_count(
            "--max-patches",
            n,
            MAX_PATCHES,
            "form factors cost time and memory growing with its square",
        )?;
    }
    if let Some(n) = scene.samples {
        check_count("--samples", n, MAX_SAMPLES, "kernel evaluations per pair of patches")?;
    }
    check_count("--rays", scene.rays, MAX_RAYS, "occlusion rays per pair of patches")?;
    if let Some(t) = scene.threads {
        check_count("--threads", t, MAX_THREADS, "worker threads")?;
    }
    if let Some(e) = scene.max_patch_edge {
        if !(e.is_finite() && e > 0.0) {
            return Err(format!("--max-patch-edge {e}: must be a positive length").into());
        }
    }
    Ok(())
}

/// Checks that every file in `paths` can be written ([`files::check_output_file`]), before any work.
fn check_outputs<P: AsRef<Path>>(paths: impl IntoIterator<Item = P>) -> Result<(), BoxError> {
    for path in paths {
        files::check_output_file(path.as_ref())?;
    }
    Ok(())
}

/// The light-map options of `--texel-size` / `--face-texels`, checked before any work.
fn light_map_options(args: &args::LightMapArgs) -> Result<LightMapOptions, BoxError> {
    use radiosity_host::picture::lightmap::MAX_FACE_SIDE;
    radiosity_host::limits::check_count(
        "--face-texels",
        args.face_texels as usize,
        MAX_FACE_SIDE as usize,
        "texels across the largest face",
    )?;
    if let Some(t) = args.texel_size {
        if !(t.is_finite() && t > 0.0) {
            return Err(format!("--texel-size {t}: must be a positive length").into());
        }
    }
    Ok(LightMapOptions {
        texel_size: args.texel_size,
        max_face_texels: args.face_texels,
        ..LightMapOptions::default()
    })
}

/// The files of a plot written to `stem` ([`radiosity_host::picture::plot::Plot::write`]).
fn plot_files(stem: &Path) -> [PathBuf; 2] {
    [stem.with_extension("svg"), stem.with_extension("png")]
}

/// Reads the table at `path` and validates it with the device's parser, before any work.
fn read_table(path: &Path) -> Result<Vec<u8>, BoxError> {
    let bytes = std::fs::read(path).map_err(|e| format!("reading table {}: {e}", path.display()))?;
    radiosity_core::Table::parse(&bytes).map_err(|e| format!("table {}: {e}", path.display()))?;
    Ok(bytes)
}

/// The default `--epsilon` of brightness refinement where the product is the f64 answer itself (`solve`,
/// `render`, `lightmap`, `export`), with the sender's unevenness charged ([`ANSWER_SENDER_WEIGHT`]): where the
/// bench's Cornell box rows (`bench/REPORT.md`, "Hierarchy against flat") put every face within 1% of the
/// continuous reference; device tables keep [`DEFAULT_EPSILON`], sized for a device's memory.
const ANSWER_EPSILON: f64 = 0.0005;

/// What a hierarchical solve is for, which sets its defaults: both refine by brightness unless `--refinement`
/// says otherwise; an f64 answer (`solve`, `render`, `lightmap`, `export`) at [`ANSWER_EPSILON`] with the
/// sender's unevenness charged [`ANSWER_SENDER_WEIGHT`] times, a device table (`bake`, `check`) at
/// [`DEFAULT_EPSILON`] without it (also the default of `--refinement budgets` everywhere).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Purpose {
    Answer,
    Table,
}

/// The scene of `scene` solved hierarchically with the given options (the rest at their defaults for
/// `purpose`), with the scene's warnings, repair notes and the solve's statistics on stderr unless `--quiet`.
fn hierarchical_solution(
    scene: &args::SceneArgs,
    hierarchy: &args::HierarchyArgs,
    purpose: Purpose,
    solver: Option<args::HierarchySolverArg>,
) -> Result<(Scene, HierarchicalSolution, HierarchyOptions), BoxError> {
    if scene.asks_for_a_mesh() {
        return Err("--no-subdivide, --max-patches and --max-patch-edge apply to --method flat only (the \
                    hierarchy subdivides where --epsilon asks)"
            .into());
    }
    let refinement = hierarchy.refinement.map_or(Refinement::Brightness, Into::into);
    let default_epsilon = match (purpose, refinement) {
        (Purpose::Answer, Refinement::Brightness) => ANSWER_EPSILON,
        _ => DEFAULT_EPSILON,
    };
    let options = HierarchyOptions {
        epsilon: hierarchy.epsilon.unwrap_or(default_epsilon),
        solver: solver.map_or_else(Default::default, Into::into),
        refinement,
        max_links: hierarchy.max_links.unwrap_or(DEFAULT_MAX_LINKS),
        pieces: hierarchy.pieces.map_or(radiosity_host::hierarchy::DEFAULT_PIECES, |n| n as usize),
        sender_weight: match (purpose, refinement) {
            (Purpose::Answer, Refinement::Brightness) => ANSWER_SENDER_WEIGHT,
            _ => 0.0,
        },
        form_factors: FormFactorOptions {
            progress: false,
            samples_per_patch: match (purpose, scene.samples) {
                (_, Some(samples)) => samples,
                (Purpose::Answer, None) => ANSWER_SAMPLES_PER_PATCH,
                (Purpose::Table, None) => FormFactorOptions::default().samples_per_patch,
            },
            ..scene.prepare_options().form_factors
        },
        progress: !scene.quiet,
        ..HierarchyOptions::default()
    };
    // Before loading: a large scene's repair takes a while, and a bad option needs none of it.
    options.validate()?;
    let mut loaded = Scene::load(&scene.scene)?;
    if !scene.quiet {
        for w in &loaded.warnings {
            eprintln!("warning: {w}");
        }
    }
    // The hierarchy meshes its roots with the scene's own setting, so --no-repair goes there.
    if scene.no_repair {
        loaded.meshing.repair = Some(false);
    }
    let start = std::time::Instant::now();
    let solution = solve_hierarchical_noting(&loaded, &options, |report| {
        if !scene.quiet {
            for note in report.notes(&scene.scene) {
                eprintln!("repair: {note}");
            }
        }
    })
    .map_err(|e| format!("{}: {e}", scene.scene.display()))?;
    if !scene.quiet {
        eprintln!("{}: {} in {:.2} s", scene.scene.display(), solution.stats, start.elapsed().as_secs_f64());
    }
    Ok((loaded, solution, options))
}

/// `solve --continuous`'s reference settings (`None` without it), checked before any work.
fn continuous_settings(
    scene: &args::SceneArgs,
    reference: &args::ContinuousArgs,
) -> Result<Option<ReferenceOptions>, BoxError> {
    let settings = reference.options(scene);
    if let Some(s) = &settings {
        radiosity_host::montecarlo::validate_options(s)?;
    }
    Ok(settings)
}

/// The discretization component of an f64 answer `b` on `patches` (a flat mesh or the hierarchy's leaves) of
/// `scene`: the continuous reference path traced with `settings`, compared face by face.
fn against_continuous(
    scene: &Scene,
    patches: &[radiosity_host::patch::Patch],
    b: &[Rgb],
    settings: &ReferenceOptions,
) -> Result<radiosity_host::evaluate::Discretization, BoxError> {
    let continuous = radiosity_host::montecarlo::continuous_reference(scene, settings)?;
    Ok(radiosity_host::evaluate::discretization(patches, b, &continuous)?)
}

/// The error for hierarchical settings given with `--method flat`.
fn reject_hierarchy_args(hierarchy: &args::HierarchyArgs) -> Result<(), BoxError> {
    if hierarchy.any() {
        return Err(
            "--epsilon, --refinement, --max-links and --pieces apply to --method hierarchical only".into()
        );
    }
    Ok(())
}

/// The scene solved in f64 at its default light intensities for a picture (`render`, `lightmap`, `export`): the
/// scene, the patches (the adaptive mesh's, or with `--method hierarchical` the hierarchy's leaves, at the f64
/// answers' defaults, [`Purpose::Answer`]) and their radiosity.
fn solve_for_pictures(
    scene: &args::SceneArgs,
    method: SolveMethod,
    hierarchy: &args::HierarchyArgs,
) -> Result<(Scene, Vec<radiosity_host::patch::Patch>, Vec<Rgb>), BoxError> {
    match method {
        SolveMethod::Flat => {
            reject_hierarchy_args(hierarchy)?;
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            let b = view::solve_default(&p)?;
            Ok((p.scene, p.patches, b))
        }
        SolveMethod::Hierarchical => {
            let (loaded, solution, _) = hierarchical_solution(scene, hierarchy, Purpose::Answer, None)?;
            Ok((loaded, solution.leaves, solution.b))
        }
    }
}

/// `radiosity solve --method hierarchical`: the leaves' patch table (CSV), or the statistics and mean radiosity
/// (text; JSON adds the radiosity per leaf).
fn solve_hierarchical_command(
    scene: &args::SceneArgs,
    format: Format,
    hierarchy: &args::HierarchyArgs,
    solver: Option<args::HierarchySolverArg>,
    continuous: Option<&ReferenceOptions>,
    out: &mut impl Write,
) -> Result<(), BoxError> {
    let (loaded, solution, options) = hierarchical_solution(scene, hierarchy, Purpose::Answer, solver)?;
    let discretization = continuous
        .map(|settings| against_continuous(&loaded, &solution.leaves, &solution.b, settings))
        .transpose()?;
    let area: f64 = solution.leaves.iter().map(|q| q.area).sum();
    let mean_of =
        |v: &[Rgb]| solution.leaves.iter().zip(v).fold(Rgb::ZERO, |m, (q, &b)| m + q.area * b / area);
    let mean = mean_of(&solution.b);
    // The answer split by source: the static lights, then each dynamic group at unit intensity.
    let transfer =
        solution.transfer.as_ref().ok_or("the hierarchical solve returned no per-source answer")?;
    let groups: Vec<(&str, Rgb)> = radiosity_host::lighting::PatchLighting::new(&loaded, &[])
        .dynamic_groups
        .iter()
        .zip(&transfer.t)
        .map(|(&g, t)| (loaded.light_groups[g].name.as_str(), mean_of(t)))
        .collect();
    let solver = match options.solver {
        radiosity_host::hierarchy::HierarchySolver::Gathering => "gathering",
        radiosity_host::hierarchy::HierarchySolver::Shooting => "shooting",
    };
    match format {
        Format::Csv => {
            write_patch_csv(out, &solution.leaves, &solution.rho, &solution.emission, &solution.b)?;
            if let Some(d) = &discretization {
                eprint!("{d}");
            }
        }
        Format::Text => {
            let rgb = |v: Rgb| format!("{:.6e} {:.6e} {:.6e}", v.x, v.y, v.z);
            writeln!(out, "{}", solution.stats)?;
            writeln!(out, "solver                 {solver}")?;
            writeln!(out, "refinement             {}", format!("{:?}", options.refinement).to_lowercase())?;
            writeln!(out, "mean radiosity         {} W/m^2 (area-weighted, default intensities)", rgb(mean))?;
            writeln!(out, "mean static radiosity  {} W/m^2", rgb(mean_of(&transfer.b_static)))?;
            for (name, response) in &groups {
                writeln!(
                    out,
                    "dynamic group {name:?}: mean response at unit intensity {} W/m^2",
                    rgb(*response)
                )?;
            }
            writeln!(out, "(--format csv prints the leaves' patch table, --format json both)")?;
            if let Some(d) = &discretization {
                write!(out, "{d}")?;
            }
        }
        Format::Json => {
            let groups: Vec<serde_json::Value> = groups
                .iter()
                .map(|(name, response)| serde_json::json!({ "group": name, "mean_unit_response": response }))
                .collect();
            let doc = serde_json::json!({
                "method": "hierarchical",
                "solver": solver,
                "discretization": discretization,
                "epsilon": options.epsilon,
                "refinement": format!("{:?}", options.refinement).to_lowercase(),
                "patches": solution.leaves.len(),
                "stats": solution.stats,
                "mean_radiosity": mean,
                "mean_static_radiosity": mean_of(&transfer.b_static),
                "dynamic_groups": groups,
                "b": solution.b,
                "error_bound": solution.error_bound,
                "patch_table": patch_json(&solution.leaves, &solution.rho, &solution.emission, &solution.b),
            });
            serde_json::to_writer_pretty(&mut *out, &doc)?;
            writeln!(out)?;
        }
    }
    Ok(())
}

/// `radiosity reference`: the continuous reference of a scene, to stdout or `--output`.
fn reference_command(args: &args::ReferenceArgs) -> Result<(), BoxError> {
    let options = args.options();
    // Bad options are reported before the scene is loaded or a ray is cast.
    radiosity_host::montecarlo::validate_options(&options)?;
    check_outputs(&args.output)?;
    let scene = Scene::load(&args.scene)?;
    if !args.quiet {
        for w in &scene.warnings {
            eprintln!("warning: {w}");
        }
    }
    let reference = radiosity_host::montecarlo::continuous_reference(&scene, &options)
        .map_err(|e| format!("{}: {e}", args.scene.display()))?;
    if !args.quiet {
        eprintln!("{}: {}", args.scene.display(), reference.summary());
    }
    let mut text = Vec::new();
    match args.format {
        Format::Text => write!(text, "{reference}")?,
        Format::Csv => reference.write_csv(&mut text)?,
        Format::Json => {
            serde_json::to_writer_pretty(&mut text, &reference)?;
            writeln!(text)?;
        }
    }
    match &args.output {
        Some(path) => files::write_atomic(path, &text)?,
        None => io::stdout().lock().write_all(&text)?,
    }
    Ok(())
}

fn run(cli: Cli) -> Result<(), BoxError> {
    let stdout = io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    match cli.command {
        Command::Formfactors { scene, format } => {
            check_scene_args(&scene)?;
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
        Command::Bake { scene, output, bits, threshold, method, transfer, format, hierarchy } => {
            // Checks that need no scene come first, whichever table the scene then asks for.
            check_scene_args(&scene)?;
            codec_for_bits(bits)?;
            if let Some(t) = threshold.filter(|t| !(0.0..1.0).contains(t)) {
                return Err(radiosity_host::bake::BakeError::BadThreshold(t).into());
            }
            check_outputs([output.clone()])?;
            match args::table_method(method, &scene, threshold.is_some(), &hierarchy)? {
                SolveMethod::Hierarchical => {
                    if threshold.is_some() {
                        return Err(
                            "--threshold applies to --method flat only (a hierarchical table keeps every link)"
                                .into(),
                        );
                    }
                    let (loaded, solution, _) =
                        hierarchical_solution(&scene, &hierarchy, Purpose::Table, None)?;
                    let baked = bake_hierarchy(&loaded, &solution, bits, transfer)?;
                    let summary = HierBakeSummary::measure(&baked, &solution)?;
                    files::write_atomic(&output, &baked.table)?;
                    match format {
                        ReportFormat::Json => {
                            let mut doc = serde_json::to_value(&summary)?;
                            doc["files"] = serde_json::json!({ "table": output });
                            serde_json::to_writer_pretty(&mut out, &doc)?;
                            writeln!(out)?;
                        }
                        ReportFormat::Text => {
                            writeln!(out, "{summary}")?;
                            writeln!(out, "wrote {}", output.display())?;
                        }
                    }
                }
                SolveMethod::Flat => {
                    reject_hierarchy_args(&hierarchy)?;
                    let threshold = threshold.unwrap_or(radiosity_host::bake::DEFAULT_THRESHOLD);
                    check_outputs([with_suffix(&output, ".capacities.json")])?;
                    let p = prepare(&scene.scene, &scene.prepare_options())?;
                    bake_to_files(&p, &output, bits, threshold, transfer, format, &mut out)?;
                }
            }
        }
        Command::Reference(args) => reference_command(&args)?,
        Command::Inspect { table, scene: _, format } if is_hierarchical_table(&table) => {
            inspect_hierarchical(&table, format, &mut out)?;
        }
        Command::Inspect { table, scene, format } => {
            let mut report = inspect_file(&table)?;
            if let Some(obj) = scene {
                let scene = Scene::load(&obj)?;
                let named = report.name_groups(scene.light_groups.iter().map(|g| g.name.as_str()));
                if named < report.groups.len() {
                    eprintln!(
                        "warning: {} of the table's {} light groups have no name in {} (a table of another scene?)",
                        report.groups.len() - named,
                        report.groups.len(),
                        obj.display()
                    );
                }
            }
            match format {
                ReportFormat::Json => {
                    serde_json::to_writer_pretty(&mut out, &report)?;
                    writeln!(out)?;
                }
                ReportFormat::Text => writeln!(out, "{report}")?,
            }
        }
        Command::Demo { out: dir, no_qemu } => {
            files::check_output_folder(&dir)?;
            files::create_output_folder(&dir)?;
            demo(&dir, !no_qemu, &mut out)?;
        }
        Command::Bench(args) => {
            if let Some(reps) = args.reps {
                use radiosity_host::limits::{check_count, MAX_REPS};
                check_count("--reps", reps, MAX_REPS, "repetitions of every timed run")?;
            }
            files::check_output_folder(&args.out)?;
            radiosity_host::bench::run(&args.options())?;
            writeln!(out, "wrote {}", args.out.join("REPORT.md").display())?;
        }
        Command::Solve { scene, format, method, hierarchy, solver, reference }
            if args::answer_method(method, &scene) == SolveMethod::Hierarchical =>
        {
            check_scene_args(&scene)?;
            let continuous = continuous_settings(&scene, &reference)?;
            solve_hierarchical_command(&scene, format, &hierarchy, solver, continuous.as_ref(), &mut out)?;
        }
        Command::Solve { scene, format, method: _, hierarchy, solver, reference } => {
            reject_hierarchy_args(&hierarchy)?;
            if solver.is_some() {
                return Err(
                    "--solver applies to --method hierarchical only (the flat solve is exact: dense LU, \
                            or Gauss-Seidel above 4096 patches)"
                        .into(),
                );
            }
            check_scene_args(&scene)?;
            let continuous = continuous_settings(&scene, &reference)?;
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            let l = &p.lighting;
            let tv = exact_transfer(l, &p.form_factors, &Method::for_size(p.patches.len()))?;
            let b = tv.relight(&l.default_intensity)?;
            let discretization = continuous
                .map(|settings| against_continuous(&p.scene, &p.patches, &b, &settings))
                .transpose()?;
            let e = l.default_emission();
            let area: f64 = p.patches.iter().map(|q| q.area).sum();
            let mean = |v: &[Rgb]| -> Rgb {
                p.patches.iter().zip(v).fold(Rgb::ZERO, |m, (q, &x)| m + q.area * x / area)
            };
            let groups: Vec<(&str, Rgb)> = l
                .dynamic_groups
                .iter()
                .zip(&tv.t)
                .map(|(&g, t)| (p.scene.light_groups[g].name.as_str(), mean(t)))
                .collect();
            match format {
                Format::Csv => {
                    write_patch_csv(&mut out, &p.patches, &l.rho, &e, &b)?;
                    if let Some(d) = &discretization {
                        eprint!("{d}");
                    }
                }
                Format::Text => {
                    let rgb = |v: Rgb| format!("{:.6e} {:.6e} {:.6e}", v.x, v.y, v.z);
                    writeln!(out, "patches                {}", p.patches.len())?;
                    writeln!(out, "relative residual      {:.3e}", tv.residual)?;
                    writeln!(
                        out,
                        "mean radiosity         {} W/m^2 (area-weighted, default intensities)",
                        rgb(mean(&b))
                    )?;
                    writeln!(out, "mean static radiosity  {} W/m^2", rgb(mean(&tv.b_static)))?;
                    for (name, response) in &groups {
                        writeln!(
                            out,
                            "dynamic group {name:?}: mean response at unit intensity {} W/m^2",
                            rgb(*response)
                        )?;
                    }
                    writeln!(out, "(--format csv prints the patch table, --format json both)")?;
                    if let Some(d) = &discretization {
                        write!(out, "{d}")?;
                    }
                }
                Format::Json => {
                    let groups: Vec<serde_json::Value> = groups
                        .iter()
                        .map(|(name, response)| serde_json::json!({ "group": name, "mean_unit_response": response }))
                        .collect();
                    let doc = serde_json::json!({
                        "method": "flat",
                        "patches": p.patches.len(),
                        "discretization": discretization,
                        "relative_residual": tv.residual,
                        "mean_radiosity": mean(&b),
                        "mean_static_radiosity": mean(&tv.b_static),
                        "dynamic_groups": groups,
                        "b": b,
                        "patch_table": patch_json(&p.patches, &l.rho, &e, &b),
                    });
                    serde_json::to_writer_pretty(&mut out, &doc)?;
                    writeln!(out)?;
                }
            }
        }
        Command::Render { scene, method, hierarchy, camera, width, height, mode, table, output } => {
            check_scene_args(&scene)?;
            // A device table's error map is the flat solve's picture: the default there.
            let method = match (method, mode) {
                (None, RenderModeArg::Error) => SolveMethod::Flat,
                _ => args::answer_method(method, &scene),
            };
            radiosity_host::limits::check_image_size("--width/--height", width, height)?;
            let camera = camera.map(|c| Camera::parse(&c)).transpose()?;
            if table.is_some() && !matches!(mode, RenderModeArg::Error) {
                return Err(
                    "--table applies to --mode error only (shaded, flat and patches pictures show the f64 \
                            solve of the scene)"
                        .into(),
                );
            }
            match (method, mode) {
                (SolveMethod::Hierarchical, RenderModeArg::Error) => {
                    return Err(
                        "--mode error shows a flat device table's error against the flat f64 solve: it \
                                takes --method flat"
                            .into(),
                    );
                }
                (SolveMethod::Flat, _) => reject_hierarchy_args(&hierarchy)?,
                (SolveMethod::Hierarchical, _) => {}
            }
            let table = table.as_deref().map(read_table).transpose()?;
            check_outputs([&output])?;
            let options = |mode| view::RenderOptions { camera, width, height, mode };
            let image = match mode {
                RenderModeArg::Error => {
                    let p = prepare(&scene.scene, &scene.prepare_options())?;
                    let exact = view::solve_default(&p)?;
                    let bytes = match table {
                        Some(bytes) => bytes,
                        None => table_bytes(&p, None)?,
                    };
                    let intensity: Vec<[f32; 3]> =
                        p.lighting.default_intensity.iter().map(|v| v.as_vec3().to_array()).collect();
                    let b = relight::device_answer(&bytes, &intensity)?;
                    view::render_scene(
                        p.surfaces(),
                        &b,
                        &options(view::RenderMode::Error { reference: &exact }),
                    )?
                }
                RenderModeArg::Shaded | RenderModeArg::Flat | RenderModeArg::Patches => {
                    let mode = match mode {
                        RenderModeArg::Shaded => view::RenderMode::Shaded,
                        RenderModeArg::Flat => view::RenderMode::Flat,
                        _ => view::RenderMode::Patches,
                    };
                    let (loaded, patches, b) = solve_for_pictures(&scene, method, &hierarchy)?;
                    let surfaces = view::Surfaces { scene: &loaded, patches: &patches };
                    view::render_scene(surfaces, &b, &options(mode))?
                }
            };
            write_png(&output, &image)?;
            writeln!(out, "{}", output.display())?;
        }
        Command::Relight { scene, table, scripts, script, qemu, frames, frame_size, csv, plot, format } => {
            check_scene_args(&scene)?;
            let scripts = scripts.unwrap_or_else(|| scene.scene.with_extension("relight.toml"));
            let loaded = firmware_sim::script::ScriptFile::load(&scripts)
                .map_err(|e| format!("relight scripts {}: {e}", scripts.display()))?;
            if let Some(name) = &script {
                if !loaded.scripts.iter().any(|s| &s.name == name) {
                    let names: Vec<&str> = loaded.scripts.iter().map(|s| s.name.as_str()).collect();
                    return Err(format!(
                        "relight scripts {}: no script named {name:?} (the file has: {})",
                        scripts.display(),
                        names.join(", ")
                    )
                    .into());
                }
            }
            let table = table.map(|t| read_table(&t).map(|bytes| (t, bytes))).transpose()?;
            if frames.is_some() {
                radiosity_host::limits::check_image_size("--frame-size", frame_size, frame_size)?;
            }
            if let Some(dir) = &frames {
                files::check_output_folder(dir)?;
            }
            check_outputs(csv.iter().cloned().chain(plot.iter().flat_map(|stem| plot_files(stem))))?;
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            let (table_path, bytes, _temp) = match table {
                Some((path, bytes)) => (path, bytes, None),
                None => {
                    let bytes = table_bytes(&p, None)?;
                    let path =
                        std::env::temp_dir().join(format!("radiosity-relight-{}.rft", std::process::id()));
                    files::write_atomic(&path, &bytes)?;
                    (path.clone(), bytes, Some(TempFile(path)))
                }
            };
            let options =
                relight::RelightOptions { only: script, qemu, ..relight::RelightOptions::default() };
            let report = relight::relight(&p, &bytes, &table_path, &scripts, &options)?;
            // The results first, so that a failure writing an output file loses none of them.
            match format {
                Format::Text => write!(out, "{report}")?,
                Format::Csv => write!(out, "{}", report.to_csv())?,
                Format::Json => {
                    serde_json::to_writer_pretty(&mut out, &report)?;
                    writeln!(out)?;
                }
            }
            out.flush()?;
            // The paths of the files written follow the text; they would break a CSV or JSON document.
            let mut stderr = io::stderr();
            let paths: &mut dyn Write = if format == Format::Text { &mut out } else { &mut stderr };
            write_relight_outputs(
                &p,
                &report,
                frames.as_deref(),
                frame_size,
                csv.as_deref(),
                plot.as_deref(),
                paths,
            )?;
        }
        Command::Lightmap { scene, method, hierarchy, output, light_map } => {
            check_scene_args(&scene)?;
            let method = args::answer_method(method, &scene);
            let options = light_map_options(&light_map)?;
            check_outputs(["exr", "hdr", "png", "json"].map(|e| output.with_extension(e)))?;
            let (loaded, patches, b) = solve_for_pictures(&scene, method, &hierarchy)?;
            let surfaces = view::Surfaces { scene: &loaded, patches: &patches };
            let files = view::write_light_map(surfaces, &b, &output, &options)?;
            for path in &files.paths {
                writeln!(out, "{}", path.display())?;
            }
            writeln!(
                out,
                "atlas {} x {} texels, texel {:.4e} scene units",
                files.width, files.height, files.texel_size
            )?;
        }
        Command::Export { scene, method, hierarchy, output, light_map } => {
            check_scene_args(&scene)?;
            let method = args::answer_method(method, &scene);
            let options = light_map_options(&light_map)?;
            if output.extension().is_none_or(|e| !e.eq_ignore_ascii_case("glb")) {
                return Err(format!("{}: the output must be a .glb file", output.display()).into());
            }
            check_outputs([output.clone(), output.with_extension("exr")])?;
            let stage = |what: &str| {
                if !scene.quiet {
                    eprintln!("export: {what}");
                }
            };
            stage(match method {
                SolveMethod::Flat => "solving the adaptive mesh in f64",
                SolveMethod::Hierarchical => "solving hierarchically in f64",
            });
            let (loaded, patches, b) = solve_for_pictures(&scene, method, &hierarchy)?;
            stage(&format!(
                "baking the light map of {} and writing the .glb",
                counted(patches.len(), "patch", "patches")
            ));
            let files = view::export_glb(
                view::Surfaces { scene: &loaded, patches: &patches },
                &b,
                &output,
                &options,
            )?;
            writeln!(out, "{}", files.glb.display())?;
            writeln!(out, "{}", files.exr.display())?;
            writeln!(
                out,
                "{}, atlas {} x {} texels (texel {:.4e} scene units), light-map intensity {:.6e} W/m^2",
                counted(files.triangles, "triangle", "triangles"),
                files.width,
                files.height,
                files.texel_size,
                files.irradiance_scale
            )?;
        }
        Command::Convert { scene, output, quiet } => {
            let ext = output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
            let bin = output.with_extension("bin");
            match ext.as_deref() {
                Some("glb") => check_outputs([&output])?,
                Some("gltf") => check_outputs([&output, &bin])?,
                _ => {
                    return Err(
                        format!("{}: the output must be a .glb or .gltf file", output.display()).into()
                    )
                }
            }
            let loaded = Scene::load(&scene)?;
            if !quiet {
                for w in &loaded.warnings {
                    eprintln!("warning: {w}");
                }
            }
            let gltf = SceneGltf::of(&loaded).map_err(|e| format!("{}: {e}", scene.display()))?;
            let fail = |e: String| format!("{}: {e}", output.display());
            if ext.as_deref() == Some("glb") {
                files::write_atomic(&output, &gltf.to_glb().map_err(fail)?)?;
            } else {
                let uri = bin.file_name().and_then(|n| n.to_str()).ok_or_else(|| {
                    format!(
                        "{}: the buffer's file name must be UTF-8 (it is a URI in the .gltf)",
                        bin.display()
                    )
                })?;
                let (json, bytes) = gltf.to_gltf(uri).map_err(fail)?;
                files::write_atomic(&bin, bytes)?;
                files::write_atomic(&output, &json)?;
                writeln!(out, "{}", bin.display())?;
            }
            writeln!(out, "{}", output.display())?;
            writeln!(
                out,
                "{}, {}",
                counted(loaded.faces.len(), "face", "faces"),
                counted(loaded.materials.len(), "material", "materials")
            )?;
        }
        Command::View { scene, web, wasm } => {
            check_scene_args(&scene)?;
            if !wasm.is_file() {
                return Err(format!(
                    "{}: no WebAssembly build of the viewer's core; build it with `cargo build -p radiosity-web \
                     --release --target wasm32-unknown-unknown --target-dir target/web` (or `make web`), or pass \
                     --wasm FILE",
                    wasm.display()
                )
                .into());
            }
            let p = prepare(&scene.scene, &scene.prepare_options())?;
            if !scene.quiet {
                eprintln!("view: baking the table and solving the f64 transfer vectors");
            }
            let files = radiosity_host::web::write_viewer(&p, &web, &wasm)?;
            for f in &files.files {
                writeln!(out, "{}", f.display())?;
            }
            writeln!(
                out,
                "{} patches, table {} bytes. Serve the folder and open the address it prints:\n  python3 -m \
                 http.server -d {}",
                files.patches,
                files.table_bytes,
                files.dir.display()
            )?;
        }
        Command::Check { scene, table_scene, method, hierarchy, check, plot, format } => {
            // A table file (with --scene, or a .rft given alone: refused below with its own message) is flat.
            let flat_setting = table_scene.is_some()
                || check.has_flat_settings()
                || scene.scene.extension().is_some_and(|e| e == "rft");
            // Checks that need no scene come first, whichever table the scene then asks for.
            check_scene_args(&scene)?;
            if let Some(stem) = &plot {
                check_outputs(plot_files(stem))?;
            }
            radiosity_host::check::check_options(&check.options(&scene))?;
            let method = args::table_method(method, &scene, flat_setting, &hierarchy)?;
            match method {
                SolveMethod::Flat => reject_hierarchy_args(&hierarchy)?,
                SolveMethod::Hierarchical => {
                    check.reject_flat_settings()?;
                    if table_scene.is_some() {
                        return Err(
                            "--method hierarchical bakes its table from the scene: checking a table \
                                    file is for flat tables (run `radiosity relight` on a hierarchical one)"
                                .into(),
                        );
                    }
                }
            }
            if table_scene.is_none() && scene.scene.extension().is_some_and(|e| e == "rft") {
                return Err(format!(
                    "{} is a table: give the scene it was baked from with --scene SCENE.obj",
                    scene.scene.display()
                )
                .into());
            }
            let report = match table_scene {
                None if method == SolveMethod::Hierarchical => {
                    let options = check.options(&scene);
                    let (loaded, solution, _) =
                        hierarchical_solution(&scene, &hierarchy, Purpose::Table, None)?;
                    radiosity_host::check::check_hierarchical(&loaded, &solution, &options)?
                }
                Some(obj) => radiosity_host::check::check_table_file(
                    &scene.scene,
                    &obj,
                    &scene.prepare_options(),
                    &check.options(&scene),
                )?,
                None => radiosity_host::check::check_scene(
                    &scene.scene,
                    &scene.prepare_options(),
                    &check.options(&scene),
                )?,
            };
            match format {
                ReportFormat::Json => writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?,
                ReportFormat::Text => write!(out, "{report}")?,
            }
            if let Some(stem) = plot {
                let (elements, _) = report.element_names();
                let title =
                    format!("Error decomposition: {} ({} {elements})", scene.scene.display(), report.patches);
                let (svg, png) = report.decomposition_plot(&title).write(&stem, 800, 500)?;
                // After JSON the paths would break the document: they go to stderr.
                match format {
                    ReportFormat::Text => writeln!(out, "{}\n{}", svg.display(), png.display())?,
                    ReportFormat::Json => eprintln!("{}\n{}", svg.display(), png.display()),
                }
            }
        }
        Command::Regress { regress, format } => {
            if regress.update {
                check_outputs([&regress.baseline])?;
            }
            let report = radiosity_host::regress::run(&regress.options())?;
            match format {
                ReportFormat::Json => writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?,
                ReportFormat::Text => write!(out, "{report}")?,
            }
            if !report.passed() {
                out.flush()?;
                return Err(format!(
                    "regression: {} over {} limit, {}",
                    counted(report.failures().len(), "value", "values"),
                    if report.failures().len() == 1 { "its" } else { "their" },
                    counted(report.problems.len(), "problem", "problems")
                )
                .into());
            }
        }
    }
    out.flush()?;
    Ok(())
}

/// Whether the file at `path` starts like a hierarchical table (format version 5); `false` if it cannot be read
/// (the flat inspection then reports why).
fn is_hierarchical_table(path: &std::path::Path) -> bool {
    std::fs::read(path).is_ok_and(|bytes| {
        matches!(radiosity_core::Table::parse(&bytes), Err(radiosity_core::TableError::HierarchicalTable))
    })
}

/// `radiosity inspect` of a hierarchical table: validated by core's parser, with its counts and sizes.
fn inspect_hierarchical(
    path: &std::path::Path,
    format: ReportFormat,
    out: &mut impl Write,
) -> Result<(), BoxError> {
    let bytes = std::fs::read(path).map_err(|e| format!("reading {}: {e}", path.display()))?;
    let table = radiosity_core::HierTable::parse(&bytes)
        .map_err(|e| format!("{}: invalid hierarchical table: {e}", path.display()))?;
    let ram = radiosity_core::HierBufferSizes::of(&table).bytes::<f32>();
    let fields: Vec<(&str, serde_json::Value)> = vec![
        ("format_version", 4.into()),
        ("bytes", bytes.len().into()),
        ("nodes", table.node_count().into()),
        ("leaves", table.leaf_count().into()),
        ("link_entries", table.link_count().into()),
        ("materials", table.material_count().into()),
        ("light_groups", table.group_count().into()),
        ("ff_bits", table.codec().bits.into()),
        ("base_solved", table.base_solved().into()),
        ("max_depth", table.max_depth().into()),
        ("longest_run", table.longest_run().into()),
        ("solver_ram_f32", ram.into()),
        ("fingerprint", format!("{:016x}", table.fingerprint()).into()),
        ("crc", format!("{:08x}", table.crc()).into()),
    ];
    let doc: serde_json::Map<String, serde_json::Value> =
        fields.iter().map(|(k, v)| ((*k).to_owned(), v.clone())).collect();
    match format {
        ReportFormat::Json => {
            serde_json::to_writer_pretty(&mut *out, &doc)?;
            writeln!(out)?;
        }
        ReportFormat::Text => {
            writeln!(out, "{}: hierarchical table (format version 5), valid", path.display())?;
            for (key, value) in &fields {
                writeln!(out, "{key:<16} {value}")?;
            }
        }
    }
    Ok(())
}

/// Bakes `p` into `output` (plus the capacities files beside it) and prints the summary.
fn bake_to_files(
    p: &Prepared,
    output: &std::path::Path,
    bits: u32,
    threshold: f64,
    transfer: bool,
    format: ReportFormat,
    out: &mut impl Write,
) -> Result<(), BoxError> {
    let options = BakeOptions { threshold, codec: codec_for_bits(bits)?, transfer, ..BakeOptions::default() };
    let input = BakeInput::from_scene(&p.scene, &p.patches, &p.lighting, &p.form_factors);
    let baked = bake(&input, &options)?;
    let evaluation = evaluate(&input, &baked, &EvaluateOptions::for_bake(p.patches.len(), &options))?;
    let summary = BakeSummary::new(&baked, &evaluation);
    let write = |path: PathBuf, bytes: &[u8]| -> Result<PathBuf, BoxError> {
        files::write_atomic(&path, bytes)?;
        Ok(path)
    };
    let table = write(output.to_path_buf(), &baked.table)?;
    let json = write(
        with_suffix(output, ".capacities.json"),
        serde_json::to_string_pretty(&baked.capacities)?.as_bytes(),
    )?;
    let fit = DeviceFit::of(&baked.capacities, &firmware_sim::qemu::MPS2_AN386);
    match format {
        ReportFormat::Json => {
            let mut doc = serde_json::to_value(&summary)?;
            doc["device_fit"] = serde_json::to_value(&fit)?;
            doc["files"] = serde_json::json!({ "table": table, "capacities": json });
            serde_json::to_writer_pretty(&mut *out, &doc)?;
            writeln!(out)?;
        }
        ReportFormat::Text => {
            writeln!(out, "{summary}")?;
            writeln!(out, "device fit         {fit}")?;
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
    out: &mut dyn Write,
) -> Result<(), BoxError> {
    if let Some(dir) = frames {
        let paths = relight::write_frames(p, report, dir, frame_size, frame_size)?;
        if let (Some(first), Some(last)) = (paths.first(), paths.last()) {
            writeln!(out, "frames of {}: {} .. {}", report.first_script, first.display(), last.display())?;
        }
    }
    if let Some(path) = csv {
        files::write_atomic(path, report.to_csv().as_bytes())?;
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

/// Patch budget of the demo's device table: with 16-bit codes its table plus the firmware's code fit the 512 KiB
/// flash of the emulated Cortex-M4 board (`make demo` prints both sizes).
const DEVICE_PATCH_BUDGET: usize = 400;

/// The main job on the Cornell box: prepare, bake, validate the table with the device's parser, draw, bake the
/// device table and relight it on the host and (with `qemu`) under QEMU.
fn demo(dir: &std::path::Path, qemu: bool, out: &mut impl Write) -> Result<(), BoxError> {
    let scene = cornell_box_path();
    writeln!(out, "== Cornell box: {}", scene.display())?;
    let options = PrepareOptions {
        no_subdivide: false,
        max_patch_edge: None,
        max_patches: None,
        repair: true,
        form_factors: FormFactorOptions::default(),
        verbose: true,
    };
    let p = prepare(&scene, &options)?;
    writeln!(out, "\n== bake (16-bit codes)")?;
    let table = dir.join("cornell-box.rft");
    bake_to_files(&p, &table, 16, radiosity_host::bake::DEFAULT_THRESHOLD, false, ReportFormat::Text, out)?;
    writeln!(out, "\n== inspect {} (validated by the device's own parser)", table.display())?;
    writeln!(out, "{}", inspect_file(&table)?)?;
    writeln!(out, "\n== pictures (exact f64 solve, published camera)")?;
    let b = view::solve_default(&p)?;
    let image = view::render_scene(
        p.surfaces(),
        &b,
        &view::RenderOptions { camera: None, width: 512, height: 512, mode: view::RenderMode::Shaded },
    )?;
    let png = dir.join("cornell-box.png");
    write_png(&png, &image)?;
    writeln!(out, "{}", png.display())?;
    let light_map = view::write_light_map(
        p.surfaces(),
        &b,
        &dir.join("cornell-box-lightmap"),
        &LightMapOptions::default(),
    )?;
    for path in &light_map.paths {
        writeln!(out, "{}", path.display())?;
    }
    let glb = view::export_glb(p.surfaces(), &b, &dir.join("cornell-box.glb"), &LightMapOptions::default())?;
    writeln!(out, "{}", glb.glb.display())?;
    let bytes = std::fs::read(&table).map_err(|e| format!("reading {}: {e}", table.display()))?;
    let intensity: Vec<[f32; 3]> =
        p.lighting.default_intensity.iter().map(|v| v.as_vec3().to_array()).collect();
    let device = relight::device_answer(&bytes, &intensity)?;
    let image = view::render_scene(
        p.surfaces(),
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

    // The default mesh is sized for the pictures' quality, not for a Cortex-M4's flash (the bake above prints
    // its table size). The device gets its own bake of the same scene within a patch budget whose table plus
    // firmware code fit the 512 KiB of flash of the emulated board (mps2-an386; the QEMU run prints the flash).
    let board = firmware_sim::qemu::MPS2_AN386;
    writeln!(
        out,
        "\n== device table: the same scene within {DEVICE_PATCH_BUDGET} patches, for a {} with {} KiB of flash",
        board.name,
        board.flash / 1024
    )?;
    let device_options = PrepareOptions { max_patches: Some(DEVICE_PATCH_BUDGET), verbose: false, ..options };
    let p = prepare(&scene, &device_options)?;
    let table = dir.join("cornell-box-m4.rft");
    bake_to_files(&p, &table, 16, radiosity_host::bake::DEFAULT_THRESHOLD, false, ReportFormat::Text, out)?;
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
    if !qemu {
        writeln!(out, "(--no-qemu: the host's device loop only; no firmware build, no QEMU run)")?;
    }
    let options =
        relight::RelightOptions { only: Some(script.into()), qemu, ..relight::RelightOptions::default() };
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
    demo_hierarchical(&p.scene, &dir.join("cornell-box-m4-hier.rft"), &scripts, options.qemu, out)
}

/// The hierarchy's epsilon of the demo's hierarchical device table: chosen for an element count on the Cornell
/// box whose buffers and stack fit the Cortex-M4's 64 KiB of RAM in f32 (the demo prints the count, the QEMU run
/// the RAM).
const DEMO_HIER_EPSILON: f64 = 0.02;

/// The demo's hierarchical part: the Cornell box as a hierarchical device table (brightness refinement, with the
/// transfer basis), its bake summary, and the lights-on script on it (host f32 and fixed point, and the f32
/// firmware under QEMU), every frame and every transfer relight against the table's own f64 answer and the
/// dense f64 answer of the same leaves.
fn demo_hierarchical(
    scene: &Scene,
    table: &std::path::Path,
    scripts: &std::path::Path,
    qemu: bool,
    out: &mut impl Write,
) -> Result<(), BoxError> {
    writeln!(
        out,
        "\n== hierarchical device table: links between clusters and elements (epsilon {DEMO_HIER_EPSILON}, \
         brightness refinement), format version 5"
    )?;
    let options = HierarchyOptions {
        epsilon: DEMO_HIER_EPSILON,
        refinement: Refinement::Brightness,
        form_factors: FormFactorOptions { progress: false, ..FormFactorOptions::default() },
        ..HierarchyOptions::default()
    };
    let solution = solve_hierarchical(scene, &options)?;
    writeln!(out, "{}", solution.stats)?;
    // With the transfer basis: the firmware also relights every element from it in one pass per light change.
    let baked = bake_hierarchy(scene, &solution, 16, true)?;
    let summary = HierBakeSummary::measure(&baked, &solution)?;
    files::write_atomic(table, &baked.table)?;
    writeln!(out, "{summary}\nwrote {}", table.display())?;
    let script = "lights-on";
    writeln!(
        out,
        "\n== relight script {script:?} on {}: device loop on the host (f32, fixed point) and the Cortex-M4 f32 \
         firmware under QEMU",
        table.display()
    )?;
    let options =
        relight::RelightOptions { only: Some(script.into()), qemu, ..relight::RelightOptions::default() };
    let report = match relight::relight_hierarchical(scene, &solution, &baked, (table, scripts), &options) {
        Ok(r) => r,
        Err(e @ relight::RelightError::Qemu { .. }) => {
            writeln!(out, "QEMU run skipped: {e}\n(the host simulator's numbers follow)")?;
            let options = relight::RelightOptions { qemu: false, ..options };
            relight::relight_hierarchical(scene, &solution, &baked, (table, scripts), &options)?
        }
        Err(e) => return Err(e.into()),
    };
    write!(out, "{report}")?;
    Ok(())
}
