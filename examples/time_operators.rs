//! Times `Operators::new` on a large icosphere (and any meshes given as OFF
//! paths): `cargo run --release --example time_operators [LEVEL] [MESH.off…]`.
//! Level 8 has 655 362 vertices.

use std::time::Instant;

use dend::operators::Operators;

fn time(name: &str, m: &dend::mesh::Mesh) {
    let t = Instant::now();
    let op = Operators::new(m);
    let s = t.elapsed().as_secs_f64();
    println!(
        "{name}: V = {}, F = {}, nnz(Lbar) = {}: Operators::new {s:.3} s",
        m.num_vertices(),
        m.num_triangles(),
        op.lbar.nnz()
    );
}

fn main() {
    let mut args = std::env::args().skip(1);
    let level: u32 = args.next().map_or(8, |a| a.parse().expect("level"));
    let t = Instant::now();
    let m = dend_testkit::icosphere(level, 1.0);
    println!(
        "icosphere({level}) built (incl. Mesh::new) in {:.3} s",
        t.elapsed().as_secs_f64()
    );
    time(&format!("icosphere({level})"), &m);
    for p in args {
        let t = Instant::now();
        let m = dend_testkit::read_mesh(std::path::Path::new(&p));
        println!("{p} read in {:.3} s", t.elapsed().as_secs_f64());
        time(&p, &m);
    }
}
