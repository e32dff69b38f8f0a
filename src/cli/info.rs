//! `dend info MESH`: counts, bounding box, topology and validation result.

use std::path::PathBuf;

use anyhow::anyhow;
use clap::Args;
use dend::mesh::asset::Asset;
use dend::mesh::io::{parse_path, Format, RawMesh};
use serde::Serialize;

/// Arguments of `dend info`.
#[derive(Debug, Args)]
pub struct InfoArgs {
    /// The mesh file (.obj, .off, .ply, .stl, .gltf, .glb).
    mesh: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// What `dend info` reports.
#[derive(Debug, Serialize)]
struct Info {
    file: String,
    vertices: usize,
    triangles: usize,
    valid: bool,
    error: Option<String>,
    bounding_box: Option<[[f64; 3]; 2]>,
    edges: Option<usize>,
    boundary_loops: Option<usize>,
    components: Option<usize>,
    closed: Option<bool>,
    euler_characteristic: Option<i64>,
    genus: Option<i64>,
    unreferenced_vertices: Option<usize>,
    /// The file's own layout (glTF/GLB, OBJ): vertex counts before and
    /// after welding, and what export keeps.
    asset: Option<dend::mesh::asset::AssetInfo>,
    warnings: Vec<String>,
}

/// Reads the mesh and prints the report; an invalid mesh is an error (exit 2)
/// after the report.
pub fn run(args: InfoArgs) -> anyhow::Result<()> {
    // asset formats report the welded surface the solver deforms (what
    // `dend deform` reads); a file that fails as an asset is reported by the
    // plain reader, which names what is wrong
    let asset = match Format::from_path(&args.mesh)? {
        Format::Obj | Format::Ply | Format::Gltf | Format::Glb => Asset::read_path(&args.mesh).ok(),
        _ => None,
    };
    let raw = match &asset {
        Some(a) => RawMesh {
            positions: a.mesh().positions().to_vec(),
            triangles: a.mesh().triangles().to_vec(),
        },
        None => parse_path(&args.mesh)?,
    };
    let mut info = Info {
        file: args.mesh.display().to_string(),
        vertices: raw.positions.len(),
        triangles: raw.triangles.len(),
        valid: false,
        error: None,
        bounding_box: None,
        edges: None,
        boundary_loops: None,
        components: None,
        closed: None,
        euler_characteristic: None,
        genus: None,
        unreferenced_vertices: None,
        asset: None,
        warnings: Vec::new(),
    };
    match raw.into_mesh() {
        Ok(m) => {
            let topo = m.topology();
            let (lo, hi) = m.bounding_box();
            let loops = topo.boundary_loops().len();
            let unref = m.unreferenced_vertices();
            if !unref.is_empty() {
                info.warnings.push(format!(
                    "{} unreferenced vertices (kept), first: {}",
                    unref.len(),
                    unref[0]
                ));
            }
            info.valid = true;
            info.bounding_box = Some([lo, hi]);
            info.edges = Some(topo.edges().len());
            info.boundary_loops = Some(loops);
            info.components = Some(topo.num_components());
            info.closed = Some(loops == 0);
            info.euler_characteristic = Some(m.euler_characteristic());
            info.genus = Some(m.genus());
            info.unreferenced_vertices = Some(unref.len());
            info.asset = asset.as_ref().map(Asset::info);
        }
        Err(e) => info.error = Some(e.to_string()),
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&info)?);
    } else {
        print_text(&info);
    }
    match info.error {
        Some(e) => Err(anyhow!("invalid mesh: {e}")),
        None => Ok(()),
    }
}

fn print_text(i: &Info) {
    println!("file:        {}", i.file);
    println!("vertices:    {}", i.vertices);
    println!("triangles:   {}", i.triangles);
    if let (Some([lo, hi]), Some(e), Some(b), Some(c), Some(x), Some(g)) = (
        i.bounding_box,
        i.edges,
        i.boundary_loops,
        i.components,
        i.euler_characteristic,
        i.genus,
    ) {
        println!("edges:       {e}");
        println!(
            "bbox:        [{}, {}, {}] .. [{}, {}, {}]",
            lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
        );
        println!("components:  {c}");
        if b == 0 {
            println!("boundary:    closed");
        } else {
            println!("boundary:    {b} loops");
        }
        println!("euler char.: {x}");
        if b == 0 {
            println!("genus:       {g}");
        } else {
            println!("genus:       {g} (of the surface with its boundary loops capped)");
        }
        println!("validation:  ok");
    }
    if let Some(a) = &i.asset {
        println!(
            "asset:       {} vertices in the file's layout, {} welded ({})",
            a.asset_vertices, a.welded_vertices, a.format
        );
        if !a.attributes.is_empty() {
            println!("attributes:  {}", a.attributes.join(", "));
        }
        if !a.groups.is_empty() {
            let g: Vec<String> = a.groups.iter().map(ToString::to_string).collect();
            println!("groups:      {}", g.join(", "));
        }
        if a.dropped_triangles > 0 {
            println!(
                "warning:     {} degenerate triangles of the file are left out of the welded surface",
                a.dropped_triangles
            );
        }
    }
    for w in &i.warnings {
        println!("warning:     {w}");
    }
    if let Some(e) = &i.error {
        println!("validation:  FAILED: {e}");
    }
}
