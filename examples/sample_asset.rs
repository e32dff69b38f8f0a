//! Writes the generated game-style test asset of
//! `dend::mesh::asset::sample::tube`: a UV-mapped tube with a split UV seam,
//! hard-edged caps in a second primitive, tangents and a two-joint skin.
//!
//! ```sh
//! cargo run --example sample_asset -- tube.glb            # skinned GLB
//! cargo run --example sample_asset -- tube.gltf --nodes   # under transformed nodes, .gltf
//! dend deform tube.glb --constraints c.json -o posed.glb
//! ```

use dend::mesh::asset::sample::{tube, TubeOptions};
use dend::mesh::io::gltf::Container;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        return Err("usage: sample_asset OUT.glb|OUT.gltf [--nodes]".into());
    };
    let container = if path.ends_with(".gltf") {
        Container::Json
    } else {
        Container::Glb
    };
    let skinned = !args.iter().any(|a| a == "--nodes");
    let bytes = tube(TubeOptions {
        skinned,
        container,
        ..TubeOptions::default()
    })?;
    std::fs::write(path, &bytes)?;
    println!("wrote {path}: {} bytes", bytes.len());
    Ok(())
}
