//! `dend gen SHAPE -o FILE [--constraints C.json]`: writes a procedural
//! test shape (and, for the creature, its default edit); the rigged `limb`
//! written as `.glb`/`.gltf` is its skinned asset.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use dend::mesh::gen::{
    creature_constraints, generate, generate_asset, Shape, ShapeParams, ShapeSpec,
};
use dend::mesh::io::gltf::Container;
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
    /// Also write the shape's default constraint set (the creature's: feet
    /// fixed, the head a handle) to this JSON file, for `dend deform
    /// --constraints`. Only the creature has one.
    #[arg(long, value_name = "C.json")]
    constraints: Option<PathBuf>,
    #[command(flatten)]
    params: ShapeParams,
}

/// Generates the shape and writes it.
pub fn run(args: GenArgs) -> anyhow::Result<()> {
    if args.constraints.is_some() && args.shape != Shape::Creature {
        anyhow::bail!("--constraints: only the creature has a default constraint set");
    }
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
    // a rigged shape written as glTF keeps its skin (other formats get the mesh)
    let container = match args.output.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("glb") => Some(Container::Glb),
        Some(e) if e.eq_ignore_ascii_case("gltf") => Some(Container::Json),
        _ => None,
    };
    match container.map(|c| generate_asset(&spec, c)).transpose()? {
        Some(Some(bytes)) => std::fs::write(&args.output, bytes)
            .with_context(|| format!("cannot write {}", args.output.display()))?,
        _ => write_path_with(&args.output, mesh.positions(), mesh.triangles(), enc)?,
    }
    println!(
        "wrote {}: {} vertices, {} triangles",
        args.output.display(),
        mesh.num_vertices(),
        mesh.num_triangles()
    );
    if let Some(path) = &args.constraints {
        let json = serde_json::to_string(&creature_constraints(&mesh))?;
        std::fs::write(path, json).with_context(|| format!("cannot write {}", path.display()))?;
        println!("wrote {}: the default constraint set", path.display());
    }
    Ok(())
}
