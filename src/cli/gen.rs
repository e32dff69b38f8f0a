//! `dend gen SHAPE -o FILE`: writes a procedural test shape.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use dend::mesh::gen::{generate, Shape, ShapeParams, ShapeSpec};
use dend::mesh::io::{write_path_with, Encoding};

/// Arguments of `dend gen`.
#[derive(Debug, Args)]
pub struct GenArgs {
    /// The shape to generate.
    #[arg(value_enum)]
    shape: Shape,
    /// Output file; the format comes from the extension (.obj, .off, .ply, .stl, .gltf, .glb).
    #[arg(short, long)]
    output: PathBuf,
    /// Write PLY/STL as ASCII instead of binary little-endian.
    #[arg(long)]
    ascii: bool,
    #[command(flatten)]
    params: ShapeParams,
}

/// Generates the shape and writes it.
pub fn run(args: GenArgs) -> anyhow::Result<()> {
    let spec = ShapeSpec {
        shape: args.shape,
        params: args.params,
    };
    let mesh = generate(&spec).with_context(|| format!("cannot generate {:?}", args.shape))?;
    let enc = if args.ascii {
        Encoding::Ascii
    } else {
        Encoding::BinaryLittleEndian
    };
    write_path_with(&args.output, mesh.positions(), mesh.triangles(), enc)?;
    println!(
        "wrote {}: {} vertices, {} triangles",
        args.output.display(),
        mesh.num_vertices(),
        mesh.num_triangles()
    );
    Ok(())
}
