//! `dend curvature MESH -o OUT.csv`: per-vertex areas and curvatures.
//!
//! One CSV row per vertex, `index,area,mean_curvature,gaussian_curvature,g`,
//! after a header row, in the mesh's own units (the operators work on a
//! normalised copy with mean edge length 1; this undoes it: `A·s²`, `H/s`,
//! `K/s²`, `G/s²`). `H` is positive where the surface bends away from its
//! normal: `+1/r` on a sphere of radius `r` with outward-facing triangles.
//! `K` uses the boundary rule `(π - Σθ)/A` on boundary vertices.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use dend::operators::Operators;

/// Arguments of `dend curvature`.
#[derive(Debug, Args)]
pub struct CurvatureArgs {
    /// Input triangle mesh (OFF).
    mesh: PathBuf,
    /// Output CSV file.
    #[arg(short, long)]
    output: PathBuf,
}

/// Reads the mesh, builds its operators and writes the CSV.
pub fn run(args: &CurvatureArgs) -> anyhow::Result<()> {
    let mesh = dend::mesh::io::read_path(&args.mesh)?;
    let t = std::time::Instant::now();
    let op = Operators::new(&mesh);
    tracing::info!(
        vertices = mesh.num_vertices(),
        triangles = mesh.num_triangles(),
        seconds = t.elapsed().as_secs_f64(),
        "operators built"
    );
    let csv = to_csv(&op);
    let mut f = std::fs::File::create(&args.output)
        .with_context(|| format!("cannot create {}", args.output.display()))?;
    f.write_all(csv.as_bytes())
        .with_context(|| format!("cannot write {}", args.output.display()))?;
    Ok(())
}

/// The CSV text (header + one row per vertex) in the mesh's own units.
fn to_csv(op: &Operators) -> String {
    let (s, s2) = (op.scale, op.scale * op.scale);
    let mut out = String::with_capacity(op.num_vertices() * 96 + 64);
    out.push_str("index,area,mean_curvature,gaussian_curvature,g\n");
    for i in 0..op.num_vertices() {
        let _ = writeln!(
            out,
            "{i},{:e},{:e},{:e},{:e}",
            op.area[i] * s2,
            op.mean_curvature[i] / s,
            op.gaussian_curvature[i] / s2,
            op.g[i] / s2
        );
    }
    out
}
