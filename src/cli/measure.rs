//! `dend measure`: the paper-reproduction figures of a deformed pose
//! (design.md §10), printed as JSON on stdout, so poses made by other programs
//! (libigl ARAP in `scripts/arap_reference.py`) are measured by the same code
//! as the tests.

use std::path::PathBuf;

use anyhow::bail;
use dend::measure::{bar_slabs, bend_angles};
use dend::mesh::io;
use serde_json::json;

/// Arguments of `dend measure`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The rest mesh.
    rest: PathBuf,
    /// The deformed pose (same vertex count and order as the rest mesh).
    pose: PathBuf,
    /// Twisted bar: cross-sections in slabs between rest z = Z0 and Z1 (min
    /// area ratio, twist per slab, twist deviation from a linear ramp).
    #[arg(long, num_args = 2, value_names = ["Z0", "Z1"], allow_negative_numbers = true,
          conflicts_with = "bend", required_unless_present = "bend")]
    bar: Option<Vec<f64>>,
    /// Bent cylinder: bend angle between consecutive slabs between rest
    /// z = Z0 and Z1, and its coefficient of variation.
    #[arg(long, num_args = 2, value_names = ["Z0", "Z1"], allow_negative_numbers = true)]
    bend: Option<Vec<f64>>,
    /// Total twist (degrees, right-hand about +z) of the linear ramp the
    /// twist deviation is measured against (with --bar).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    twist: f64,
    /// Number of slabs (default 20 for --bar, 12 for --bend).
    #[arg(long)]
    slabs: Option<usize>,
}

/// Runs `dend measure`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let rest = io::read_path(&args.rest)?;
    let pose = io::read_path(&args.pose)?;
    if rest.num_vertices() != pose.num_vertices() {
        bail!(
            "the pose has {} vertices, the rest mesh {}",
            pose.num_vertices(),
            rest.num_vertices()
        );
    }
    let (range, default_slabs) = match (&args.bar, &args.bend) {
        (Some(r), _) => (r, 20),
        (None, Some(r)) => (r, 12),
        (None, None) => bail!("give --bar Z0 Z1 or --bend Z0 Z1"),
    };
    let (z0, z1) = (range[0], range[1]);
    let slabs = args.slabs.unwrap_or(default_slabs);
    if !(z0.is_finite() && z1.is_finite() && z0 < z1) {
        bail!("need finite Z0 < Z1, got {z0} {z1}");
    }
    if slabs < 3 {
        bail!("--slabs must be at least 3, got {slabs}");
    }
    let out = if args.bar.is_some() {
        let fig = bar_slabs(rest.positions(), pose.positions(), z0, z1, slabs);
        if fig.z.is_empty() {
            bail!("no slab between z = {z0} and {z1} holds 3 or more vertices");
        }
        json!({
            "min_area": fig.min_area(),
            "twist_dev_deg": fig.twist_deviation(z0, z1, args.twist),
            "slab_z": fig.z,
            "area_ratio": fig.area_ratio,
            "twist_deg": fig.twist_deg,
        })
    } else {
        let (angles, cv) = bend_angles(rest.positions(), pose.positions(), z0, z1, slabs);
        if angles.is_empty() {
            bail!("fewer than 3 non-empty slabs between z = {z0} and {z1}");
        }
        json!({
            "bend_cv": cv,
            "bend_total_deg": angles.iter().sum::<f64>(),
            "angles_deg": angles,
        })
    };
    println!("{out}");
    Ok(())
}
