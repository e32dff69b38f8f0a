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
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use dend::mesh::Mesh;
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
    let mesh = read_off(&args.mesh)?;
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

/// Temporary minimal OFF reader until `dend::mesh::io` lands in main.
fn read_off(path: &Path) -> anyhow::Result<Mesh> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut tok = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or(""))
        .flat_map(str::split_whitespace);
    if tok.next() != Some("OFF") {
        anyhow::bail!("{}: not an OFF file (missing `OFF` header)", path.display());
    }
    let mut num = |what: &str| -> anyhow::Result<f64> {
        let t = tok.next().with_context(|| {
            format!("{}: unexpected end of file reading {what}", path.display())
        })?;
        t.parse::<f64>()
            .with_context(|| format!("{}: bad number `{t}` in {what}", path.display()))
    };
    let count = |x: f64, what: &str| -> anyhow::Result<usize> {
        if x >= 0.0 && x.fract() == 0.0 && x < u32::MAX as f64 {
            Ok(x as usize)
        } else {
            anyhow::bail!("{}: bad {what} `{x}`", path.display())
        }
    };
    let nv = count(num("vertex count")?, "vertex count")?;
    let nf = count(num("face count")?, "face count")?;
    num("edge count")?;
    let mut p = Vec::with_capacity(nv.min(1 << 24));
    for v in 0..nv {
        let what = format!("vertex {v}");
        p.push([num(&what)?, num(&what)?, num(&what)?]);
    }
    let mut t = Vec::with_capacity(nf.min(1 << 24));
    for f in 0..nf {
        let what = format!("face {f}");
        let k = count(num(&what)?, "polygon size")?;
        let mut poly = Vec::with_capacity(k.min(64));
        for _ in 0..k {
            poly.push(count(num(&what)?, "vertex index")? as u32);
        }
        if k < 3 {
            anyhow::bail!("{}: face {f} has {k} vertices", path.display());
        }
        for j in 1..k - 1 {
            t.push([poly[0], poly[j], poly[j + 1]]);
        }
    }
    Mesh::new(p, t).with_context(|| format!("{}: invalid mesh", path.display()))
}
