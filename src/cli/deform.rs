//! `dend deform`: deform a mesh file with a constraints file (JSON,
//! `api/constraints.schema.json`) or a Botsch–Sorkine `.sel`/`.def` pair.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context};
use dend::deform::{
    Constraints, ConstraintsSpec, Deformer, DetailTerm, Energy, Factor, Formulation, Mode, Params,
    Rest, RigidTransform,
};
use dend::mesh::io::{self, survey};

/// Arguments of `dend deform`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The rest mesh (OBJ, OFF, PLY or STL).
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
    /// Energy: total (L²-2GL, default), total-paper (L²-2LG), thin-plate,
    /// membrane, combined.
    #[arg(long)]
    energy: Option<String>,
    /// Stretching weight k_s of the combined energy.
    #[arg(long, default_value_t = 1.0)]
    ks: f64,
    /// Bending weight k_b of the combined energy.
    #[arg(long, default_value_t = 1.0)]
    kb: f64,
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
    /// System solved: least_squares (paper eq. 24, default) or square
    /// (paper eq. 23, 4th order, sparser factor).
    #[arg(long, default_value = "least_squares")]
    formulation: String,
}

/// Runs `dend deform`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mesh =
        io::read_path(&args.mesh).with_context(|| format!("reading {}", args.mesh.display()))?;
    for v in mesh.unreferenced_vertices().iter().take(1) {
        eprintln!(
            "warning: {} unreferenced vertices (first: {v}) are kept in place",
            mesh.unreferenced_vertices().len()
        );
    }
    let mut constraints = if let Some(path) = &args.constraints {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let spec: ConstraintsSpec =
            serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))?;
        spec.resolve(&mesh)?
    } else {
        let (sel_path, def_path) = (args.sel.as_ref().unwrap(), args.def.as_ref().unwrap());
        let sel = survey::read_sel(sel_path)
            .with_context(|| format!("reading {}", sel_path.display()))?;
        sel.check_len(mesh.num_vertices())?;
        let def = survey::read_def(def_path)
            .with_context(|| format!("reading {}", def_path.display()))?;
        let fixed = sel.indices(survey::VertexStatus::Fixed);
        let handle = sel.indices(survey::VertexStatus::Handle);
        let mut c = Constraints::new(&mesh, fixed, vec![("handle".into(), handle, None)])?;
        let pivot = c.handles[0].rest_centroid;
        c.handles[0].target = RigidTransform::from_matrix(&def.matrix, pivot)?;
        c
    };
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
    let params = Params {
        energy,
        lambda1: args.soft.unwrap_or(0.0),
        lambda2: args.lambda2,
        detail: if args.linear {
            DetailTerm::Linear
        } else {
            DetailTerm::Nonlinear
        },
        mode: if args.paper {
            Mode::Paper
        } else {
            Mode::Default
        },
        tol: args.tol,
        max_iters: args.max_iters,
        anderson: args.anderson,
        formulation: Formulation::from_name(&args.formulation).with_context(|| {
            format!(
                "unknown formulation {:?} (least_squares, square)",
                args.formulation
            )
        })?,
    };
    params.validate()?;
    if args.steps == 0 {
        bail!("--steps must be at least 1");
    }
    let t0 = Instant::now();
    let rest = Arc::new(Rest::new(mesh.clone())?);
    let precompute = t0.elapsed();
    let factor = Factor::build(&rest, &params, &constraints)?;
    let ft = factor.timings();
    eprintln!(
        "mesh: {} vertices, {} triangles; free unknowns {}",
        mesh.num_vertices(),
        mesh.num_triangles(),
        factor.num_unknowns()
    );
    eprintln!(
        "precompute (operators + STEP 1): {:.1} ms; factor: assembly {:.1} ms, symbolic {:.1} ms, numeric {:.1} ms ({} nonzeros, {:.1} MB)",
        ms(precompute),
        ms(ft.assembly),
        ms(ft.symbolic),
        ms(ft.numeric),
        factor.factor_nnz(),
        factor.memory_bytes() as f64 / 1e6
    );
    let full: Vec<RigidTransform> = constraints.handles.iter().map(|h| h.target).collect();
    let mut deformer = Deformer::new(rest, params);
    let mut iterations = 0;
    let t1 = Instant::now();
    for s in 1..=args.steps {
        for (h, t) in constraints.handles.iter_mut().zip(&full) {
            h.target = t.fraction(s as f64 / args.steps as f64);
        }
        let rep = deformer.step(&factor, &constraints, args.max_iters)?;
        iterations += rep.iterations;
        eprintln!(
            "step {s}/{}: {} iterations, last update {:.2e} mean edge lengths, {}",
            args.steps,
            rep.iterations,
            rep.last_update,
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
    let solve = t1.elapsed();
    eprintln!(
        "iterations: {iterations} in {:.1} ms ({:.2} ms per iteration)",
        ms(solve),
        ms(solve) / iterations.max(1) as f64
    );
    io::write_path_with(
        &args.output,
        deformer.pose(),
        mesh.triangles(),
        Default::default(),
    )
    .with_context(|| format!("writing {}", args.output.display()))?;
    Ok(())
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
