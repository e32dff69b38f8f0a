//! `dend deform`: deform a mesh file with a constraints file (JSON,
//! `api/constraints.schema.json`) or a Botsch–Sorkine `.sel`/`.def` pair.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use dend::deform::{
    Constraints, ConstraintsSpec, Corrections, Deformer, DetailTerm, Energy, Factor, Formulation,
    Galerkin, Levels, Mode, Params, ParamsSpec, Rest, RigidTransform, StepReport,
};
use dend::mesh::asset::Asset;
use dend::mesh::io::{self, survey};

use super::preset::PresetArg;

/// Arguments of `dend deform`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The rest mesh (OBJ, OFF, PLY, STL, glTF or GLB). glTF/GLB, OBJ and PLY are
    /// read as assets: the solver deforms the welded surface (vertex indices
    /// of constraints name welded vertices) and an output of the same family
    /// keeps the file's vertex layout, UVs, skin and materials.
    mesh: PathBuf,
    /// Constraints file (JSON).
    #[arg(long, conflicts_with_all = ["sel", "def"], required_unless_present = "sel")]
    constraints: Option<PathBuf>,
    /// Survey selection file: one status per vertex (0 fixed, 1 free, 2 handle).
    #[arg(long, requires = "def")]
    sel: Option<PathBuf>,
    /// Survey handle transform (4×4 matrix).
    #[arg(long, requires = "sel")]
    def: Option<PathBuf>,
    /// Output mesh (format from the extension).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write the pose fitted onto the mesh's rig (a skinned glTF/GLB):
    /// the joints' transforms in the skeleton's nodes and the corrective
    /// as a morph target of weight 1 (.glb or .gltf). Prints the fit's
    /// residual.
    #[arg(long, value_name = "FILE")]
    output_skeleton: Option<PathBuf>,
    /// With --output-skeleton: leave the corrective morph target out.
    #[arg(long, requires = "output_skeleton")]
    no_corrective: bool,
    /// Energy: total (L²-2GL, default), total-paper (L²-2LG), thin-plate,
    /// membrane, combined.
    #[arg(long)]
    energy: Option<String>,
    /// Stretching weight k_s of the combined energy (least_squares, square).
    #[arg(long, default_value_t = 1.0)]
    ks: f64,
    /// Bending weight k_b of the combined energy (least_squares, square).
    #[arg(long, default_value_t = 1.0)]
    kb: f64,
    /// Elastic formulation: parameter preset, characters (the default: stretch 3, Laplacian share 0.1, coarse ratio 4, corrections while-gaining every 5 iterations; ARAP-like edge lengths on characters) or elastica (stretch 1, Laplacian share 1, coarse ratio 8, corrections while-faster every 10: the paper's even bend and twist, the same pose at any resolution; docs/posing.md). --stretch, --laplacian, --coarse-ratio, --corrections and --correction-period override it.
    #[arg(long, visible_alias = "weights", value_enum, default_value_t = PresetArg::Characters)]
    preset: PresetArg,
    /// Elastic formulation: stretch weight k_s (ARAP's spokes), dimensionless [default: 3, or 1 with --preset elastica].
    #[arg(long)]
    stretch: Option<f64>,
    /// Elastic formulation: bending weight β (E_T weighted β × surface area), dimensionless.
    #[arg(long, default_value_t = dend::deform::DEFAULT_BENDING)]
    bending: f64,
    /// Elastic formulation: area-preservation weight k_a, dimensionless.
    #[arg(long, default_value_t = dend::deform::DEFAULT_AREA)]
    area: f64,
    /// Elastic formulation: weight k_L of the Laplacian part of the bending energy (the rotated detail rows), dimensionless; 1 with λ2 = 1 is E_T exactly [default: 0.1, or 1 with --preset elastica].
    #[arg(long)]
    laplacian: Option<f64>,
    /// Elastic formulation: most vertices of a level per vertex of the coarse level below it (each level of the hierarchy), at least 2 [default: 4, or 8 with --preset elastica].
    #[arg(long)]
    coarse_ratio: Option<usize>,
    /// Elastic formulation: when a sequence's coarse corrections stop, while-faster (once one gains less than the fine iterations before it) or while-gaining (once one gains nothing) [default: while-gaining, or while-faster with --preset elastica].
    #[arg(long, value_parser = ["while-faster", "while-gaining"])]
    corrections: Option<String>,
    /// Elastic formulation: fine iterations between two coarse corrections, at least 1 [default: 5, or 10 with --preset elastica].
    #[arg(long)]
    correction_period: Option<usize>,
    /// Linear detail term (δ̂ = δ, paper eq. 15) instead of the nonlinear one.
    #[arg(long)]
    linear: bool,
    /// The paper read literally: unrotated internal term, cross-product μ,
    /// and the table's L²-2LG unless --energy is given.
    #[arg(long)]
    paper: bool,
    /// Soft constraints with weight λ1 (default: hard constraints).
    #[arg(long, value_name = "LAMBDA1")]
    soft: Option<f64>,
    /// Detail-term weight λ2.
    #[arg(long, default_value_t = 1.0)]
    lambda2: f64,
    /// Apply the handle transforms in N equal increments (interactive large edits).
    #[arg(long, default_value_t = 1)]
    steps: usize,
    /// Iteration limit per increment.
    #[arg(long, default_value_t = 100)]
    max_iters: usize,
    /// Anderson acceleration window (0 disables it).
    #[arg(long, default_value_t = 5)]
    anderson: usize,
    /// Convergence tolerance (largest vertex move, in mean edge lengths).
    #[arg(long, default_value_t = 1e-3)]
    tol: f64,
    /// System solved: elastic (design.md §7: E_T as an energy in rotated
    /// frames + stretch + area, monotone; default), least_squares (paper
    /// eq. 24, the default before), square or square_lu (paper eq. 23).
    /// Default: elastic, or least_squares with --paper or an energy the
    /// elastic formulation does not have (membrane, combined, total-paper).
    #[arg(long)]
    formulation: Option<String>,
    /// Levels of the elastic iteration: 2 uses a coarse mesh of about
    /// 1/coarse-ratio of the vertices (1/4 by default, 1/8 with --preset
    /// elastica), at least 500 (meshes of 1000 vertices or more whose
    /// constraint groups survive), to start an edit from the rest pose and
    /// to correct the pose every correction-period iterations (5, or 10
    /// with elastica); 1 starts from the handles' rotations spread by
    /// harmonic weights, without corrections; 3 (the default) solves the
    /// coarse problem the same way on a coarser level of its own, down to
    /// a level under 1000 vertices whose iteration takes Newton steps (a
    /// hierarchy; docs/performance.md measures it).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u8).range(1..=3))]
    levels: u8,
    /// The coarse corrections (docs/performance.md): the hierarchy's
    /// coarse problems' by default or with `off`; a setting makes them
    /// Galerkin ones, each one Newton step of the fine energy restricted
    /// to the blended rigid motions of aggregates of vertices (those
    /// nearest each vertex of coarse level DEPTH), its matrix reused for
    /// LAG corrections, one correction every PERIOD fine iterations
    /// (replacing --correction-period), the aggregates' weights smoothed
    /// SMOOTH times across their borders (0: each aggregate moves
    /// rigidly). Omitted fields take the defaults 2, 6, 1, 1; DEPTH, LAG
    /// and PERIOD are whole numbers of at least 1, SMOOTH of at least 0.
    /// The coarse start is the hierarchy's either way. A setting needs the
    /// elastic formulation and --levels 2 or 3; a mesh with fewer coarse
    /// levels than DEPTH aggregates over the levels it has.
    #[arg(long, value_name = "off|DEPTH[,LAG[,PERIOD[,SMOOTH]]]", value_parser = parse_galerkin)]
    galerkin: Option<GalerkinArg>,
    /// Print the objective after every iteration.
    #[arg(short, long)]
    verbose: bool,
    /// Write a JSON report: iterations, convergence, the objective after
    /// every iteration, timings.
    #[arg(long, value_name = "FILE")]
    report: Option<PathBuf>,
}

/// Runs `dend deform`: read, build the factor, solve the increments,
/// report, write.
pub fn run(args: Args) -> anyhow::Result<()> {
    let asset = dend::mesh::asset::Asset::read_path(&args.mesh)?;
    let mesh = asset.mesh().clone();
    for v in mesh.unreferenced_vertices().iter().take(1) {
        eprintln!(
            "warning: {} unreferenced vertices (first: {v}) are kept in place",
            mesh.unreferenced_vertices().len()
        );
    }
    let mut constraints = read_constraints(&args, &asset)?;
    let params = params_of(&args)?;
    if args.steps == 0 {
        bail!("--steps must be at least 1");
    }
    if let Some(GalerkinArg::On(_)) = args.galerkin {
        if params.elastic().is_none() {
            bail!("--galerkin applies to the elastic formulation only");
        }
        if args.levels == 1 {
            bail!("--galerkin needs coarse levels (--levels 2 or 3)");
        }
    }
    let t0 = Instant::now();
    let rest = Arc::new(Rest::new(mesh.clone())?);
    let precompute = t0.elapsed();
    let mut deformer = Deformer::new(rest, params);
    deformer.set_levels(match args.levels {
        1 => Levels::One,
        2 => Levels::Two,
        _ => Levels::Many,
    });
    // before the factor: its precomputation prepares the corrections' state
    match args.galerkin {
        Some(GalerkinArg::On(g)) => deformer.set_galerkin(Some(g)),
        Some(GalerkinArg::Off) => deformer.set_galerkin(None),
        None => {}
    }
    let galerkin = deformer.galerkin();
    // the factor, and beside it the coarse start of the first increment
    let mut first = constraints.clone();
    for h in &mut first.handles {
        h.target = increment(&h.target, 1, args.steps);
    }
    let t_factor = Instant::now();
    let factor = deformer.build_factor(&first)?;
    if galerkin.is_some() {
        // the corrections' aggregates and symbolic analysis are the
        // constraint set's precomputation, as the levels' factors are
        deformer.prepare_levels(&factor, &first);
    }
    let prepare = t_factor.elapsed();
    let ft = factor.timings();
    eprintln!(
        "mesh: {} vertices, {} triangles; free unknowns {}",
        mesh.num_vertices(),
        mesh.num_triangles(),
        factor.num_unknowns()
    );
    eprintln!(
        "precompute (operators + STEP 1): {:.1} ms; factor (with the coarse start beside it): {:.1} ms, of which assembly {:.1} ms, symbolic {:.1} ms, numeric {:.1} ms ({} nonzeros, {:.1} MB)",
        ms(precompute),
        ms(prepare),
        ms(ft.assembly),
        ms(ft.symbolic),
        ms(ft.numeric),
        factor.factor_nnz(),
        factor.memory_bytes() as f64 / 1e6
    );
    let t1 = Instant::now();
    let solved = solve(&args, &mut deformer, &factor, &mut constraints)?;
    let solve = t1.elapsed();
    eprintln!(
        "iterations: {} in {:.1} ms ({:.2} ms per iteration)",
        solved.iterations,
        ms(solve),
        ms(solve) / solved.iterations.max(1) as f64
    );
    if let Some(path) = &args.report {
        let times = (ms(precompute), ms(prepare), ms(solve));
        let mut report = solved.report(deformer.params(), &factor, mesh.num_vertices(), times);
        report["galerkin"] =
            serde_json::json!(galerkin.map(|g| [g.depth, g.lag, g.period, g.smooth]));
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let format = io::Format::from_path(&args.output)?;
    let bytes = asset.export(deformer.pose(), format)?;
    std::fs::write(&args.output, bytes)
        .with_context(|| format!("writing {}", args.output.display()))?;
    if let Some(path) = &args.output_skeleton {
        let format = io::Format::from_path(path)?;
        let poses = [("pose".to_owned(), deformer.pose())];
        let out = dend::rig::export_skeleton(&asset, &poses, false, !args.no_corrective, format)?;
        if out.renormalised > 0 {
            eprintln!(
                "warning: {} vertices' skin weights did not sum to one and were normalised",
                out.renormalised
            );
        }
        for f in &out.fits {
            eprintln!(
                "skeleton fit: residual max {:.3e}, mean {:.3e} of the diagonal ({} sweeps)",
                f.residual.max, f.residual.mean, f.sweeps
            );
        }
        std::fs::write(path, out.bytes).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// The constraints of `--constraints` (groups resolved on the asset) or of
/// the survey's `--sel`/`--def` pair, resolved on the asset's mesh.
fn read_constraints(args: &Args, asset: &Asset) -> anyhow::Result<Constraints> {
    let mesh = asset.mesh();
    if let Some(path) = &args.constraints {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let spec: ConstraintsSpec =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        // `{"group": …}` sets name the asset's parts: index lists from here on
        return Ok(asset.resolve_groups(&spec)?.resolve(mesh)?);
    }
    let (sel_path, def_path) = (args.sel.as_ref().unwrap(), args.def.as_ref().unwrap());
    let sel = survey::read_sel(sel_path)?;
    sel.check_len(mesh.num_vertices())?;
    let def = survey::read_def(def_path)?;
    let fixed = sel.indices(survey::VertexStatus::Fixed);
    let handle = sel.indices(survey::VertexStatus::Handle);
    let mut c = Constraints::new(mesh, fixed, vec![("handle".into(), handle, None)])?;
    let pivot = c.handles[0].rest_centroid;
    c.handles[0].target = RigidTransform::from_matrix(&def.matrix, pivot)?;
    Ok(c)
}

/// The solver parameters of the arguments, validated.
fn params_of(args: &Args) -> anyhow::Result<Params> {
    let energy = match &args.energy {
        Some(name) if name == "combined" => Energy::Combined {
            ks: args.ks,
            kb: args.kb,
        },
        Some(name) => Energy::from_name(name).with_context(|| {
            format!("unknown energy {name:?} (total, total-paper, thin-plate, membrane, combined)")
        })?,
        None if args.paper => Energy::TotalCurvaturePaper,
        None => Energy::TotalCurvature,
    };
    let detail = if args.linear {
        DetailTerm::Linear
    } else {
        DetailTerm::Nonlinear
    };
    let formulation = match &args.formulation {
        Some(name) => Formulation::from_name(name).with_context(|| {
            format!("unknown formulation {name:?} (elastic, least_squares, square, square_lu)")
        })?,
        None if args.paper || !energy.has_elastic_form() => Formulation::LeastSquares,
        None => Formulation::Elastic,
    };
    // the flags as the overrides of the preset a client would send: the
    // elastic weights are checked whatever the formulation, and kept by
    // the elastic one only
    let spec = ParamsSpec {
        preset: Some(args.preset.preset()),
        energy: Some(energy),
        lambda1: Some(args.soft.unwrap_or(0.0)),
        lambda2: Some(args.lambda2),
        detail: Some(detail),
        mode: Some(if args.paper {
            Mode::Paper
        } else {
            Mode::Default
        }),
        tol: Some(args.tol),
        max_iters: Some(args.max_iters),
        anderson: Some(args.anderson),
        formulation: Some(formulation),
        stretch: args.stretch,
        bending: Some(args.bending),
        area: Some(args.area),
        laplacian: args.laplacian,
        coarse_ratio: args.coarse_ratio,
        corrections: args.corrections.as_deref().map(|c| match c {
            "while-gaining" => Corrections::WhileGaining,
            _ => Corrections::WhileFaster,
        }),
        correction_period: args.correction_period,
    };
    let params = Params::try_from(spec)?;
    params.validate()?;
    Ok(params)
}

/// The target of increment `s` of `steps` towards `full` (the first one is
/// also what the coarse start is solved for beside the factor: the two
/// must be the same bits).
fn increment(full: &RigidTransform, s: usize, steps: usize) -> RigidTransform {
    full.fraction(s as f64 / steps as f64)
}

/// What the increments' iterations did (the `--report`'s figures).
#[derive(Default)]
struct Solved {
    iterations: usize,
    coarse_iterations: usize,
    coarse_ms: f64,
    objectives: Vec<f64>,
    iteration_ms: Vec<f64>,
    /// Each iteration's time less its coarse correction's.
    fine_ms: Vec<f64>,
    steps: Vec<serde_json::Value>,
    converged: bool,
    diverged: bool,
    objective_first: Option<f64>,
}

/// Solves `--steps` equal increments of the handle transforms, each up to
/// `--max-iters` iterations, printing each increment's outcome.
fn solve(
    args: &Args,
    deformer: &mut Deformer,
    factor: &Factor,
    constraints: &mut Constraints,
) -> anyhow::Result<Solved> {
    let full: Vec<RigidTransform> = constraints.handles.iter().map(|h| h.target).collect();
    let mut solved = Solved::default();
    for s in 1..=args.steps {
        for (h, t) in constraints.handles.iter_mut().zip(&full) {
            h.target = increment(t, s, args.steps);
        }
        let (rep, step_iterations) = solved.increment(args, deformer, factor, constraints)?;
        solved.iterations += step_iterations;
        solved.converged = rep.converged;
        solved.diverged |= rep.diverged;
        solved.steps.push(serde_json::json!({
            "iterations": step_iterations,
            "converged": rep.converged,
            "diverged": rep.diverged,
        }));
        eprintln!(
            "step {s}/{}: {} iterations, last update {:.2e} mean edge lengths, objective {:.6e}, {}",
            args.steps,
            step_iterations,
            rep.last_update,
            rep.objective,
            if rep.converged {
                "converged"
            } else if rep.diverged {
                "STOPPED: objective growing (best pose kept)"
            } else {
                "iteration limit reached"
            }
        );
        if rep.diverged {
            eprintln!("warning: the iteration stopped because its objective kept growing; try --steps or a larger --lambda2");
        }
    }
    Ok(solved)
}

impl Solved {
    /// One increment: iterations until converged, stopped or `--max-iters`;
    /// its last report and its iteration count.
    fn increment(
        &mut self,
        args: &Args,
        deformer: &mut Deformer,
        factor: &Factor,
        constraints: &Constraints,
    ) -> anyhow::Result<(StepReport, usize)> {
        // one iteration per call: the iteration state (Anderson history,
        // rotations, safeguard) carries over between calls on unchanged
        // targets, so this is the same sequence as one call
        let mut rep = None;
        let mut step_iterations = 0;
        while step_iterations < args.max_iters {
            let t = Instant::now();
            let r = deformer.step(factor, constraints, 1)?;
            let took = ms(t.elapsed());
            self.iteration_ms.push(took);
            self.fine_ms.push((took - r.coarse_ms).max(0.0));
            if self.objective_first.is_none() {
                self.objective_first = Some(r.initial_objective);
            }
            step_iterations += r.iterations;
            self.coarse_iterations += r.coarse_iterations;
            self.coarse_ms += r.coarse_ms;
            if r.coarse_iterations > 0 {
                eprintln!(
                    "  coarse level: {} coarse iterations in {:.1} ms",
                    r.coarse_iterations, r.coarse_ms
                );
            }
            self.objectives.push(r.objective);
            if args.verbose {
                eprintln!(
                    "  iteration {step_iterations}: objective {:.9e}, update {:.2e}",
                    r.objective, r.last_update
                );
            }
            let done = r.converged || r.diverged || r.iterations == 0;
            rep = Some(r);
            if done {
                break;
            }
        }
        let rep = rep.context("no iteration ran (--max-iters 0)")?;
        Ok((rep, step_iterations))
    }

    /// The `--report` JSON (wall times in ms: `operators` the rest
    /// operators, `prepare` the factor with the coarse start beside it,
    /// `solve` all increments; `precompute_ms + solve_ms` is the time to
    /// settle; `fine_iteration_ms_median` the median iteration less its
    /// coarse correction, `fine_iteration_equivalents` the solve in those
    /// units: with a correction after every iteration the plain
    /// iteration median includes one).
    fn report(
        &self,
        params: &Params,
        factor: &Factor,
        vertices: usize,
        (operators, prepare, solve): (f64, f64, f64),
    ) -> serde_json::Value {
        let ft = factor.timings();
        let iteration = median(&self.iteration_ms);
        let fine = median(&self.fine_ms);
        let factor_ms = ms(ft.assembly) + ms(ft.symbolic) + ms(ft.numeric);
        serde_json::json!({
            "formulation": params.formulation.kind(),
            "vertices": vertices,
            "unknowns": factor.num_unknowns(),
            "iterations": self.iterations,
            "coarse_iterations": self.coarse_iterations,
            "coarse_ms": self.coarse_ms,
            "converged": self.converged,
            "diverged": self.diverged,
            "objective_first": self.objective_first,
            "objective_last": self.objectives.last(),
            "objectives": self.objectives,
            "precompute_ms": operators + prepare,
            "operators_ms": operators,
            "prepare_ms": prepare,
            "factor_ms": factor_ms,
            "factor_assembly_ms": ms(ft.assembly),
            "factor_symbolic_ms": ms(ft.symbolic),
            "factor_numeric_ms": ms(ft.numeric),
            "factor_nnz": factor.factor_nnz(),
            "iteration_ms_median": iteration,
            "fine_iteration_ms_median": fine,
            "fine_iteration_equivalents": if fine > 0.0 { Some(solve / fine) } else { None },
            "solve_ms": solve,
            "steps": self.steps,
        })
    }
}

/// The upper median of `xs` (0 when empty).
fn median(xs: &[f64]) -> f64 {
    let mut sorted = xs.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.get(sorted.len() / 2).copied().unwrap_or(0.0)
}

/// `--galerkin`: the coarse problems' corrections, or a Galerkin setting.
#[derive(Debug, Clone, Copy)]
pub enum GalerkinArg {
    /// `off`.
    Off,
    /// `DEPTH[,LAG[,PERIOD[,SMOOTH]]]`.
    On(Galerkin),
}

/// `--galerkin off|DEPTH[,LAG[,PERIOD[,SMOOTH]]]`: omitted fields take
/// `Galerkin::default()`'s; DEPTH, LAG and PERIOD whole numbers of at
/// least 1, SMOOTH of at least 0.
fn parse_galerkin(s: &str) -> Result<GalerkinArg, String> {
    const FORM: &str = "off or DEPTH[,LAG[,PERIOD[,SMOOTH]]], e.g. 2,6,1,1";
    if s.trim() == "off" {
        return Ok(GalerkinArg::Off);
    }
    let fields: Vec<&str> = s.split(',').map(str::trim).collect();
    if fields.len() > 4 {
        return Err(format!("{s:?} has {} fields: {FORM}", fields.len()));
    }
    let d = Galerkin::default();
    let mut values = [d.depth, d.lag, d.period, d.smooth];
    let names = [("DEPTH", 1), ("LAG", 1), ("PERIOD", 1), ("SMOOTH", 0)];
    for ((value, (name, least)), field) in values.iter_mut().zip(names).zip(&fields) {
        *value = field
            .parse::<usize>()
            .ok()
            .filter(|&v| v >= least)
            .ok_or_else(|| {
                format!("{name} {field:?} is not a whole number of at least {least} ({FORM})")
            })?;
    }
    let [depth, lag, period, smooth] = values;
    Ok(GalerkinArg::On(Galerkin {
        depth,
        lag,
        period,
        smooth,
    }))
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
