//! Every mesh in `$DEND_MESHES` (default `../shared/meshes`) loads, validates
//! and matches the README's table; the survey `.sel`/`.def` files parse and
//! their conventions hold.

use std::path::PathBuf;

use dend::mesh::io::read_path;
use dend::mesh::io::survey::{read_def, read_sel, VertexStatus};

fn meshes_dir() -> Option<PathBuf> {
    dend_testkit::shared_meshes()
}

/// (file, V, F, boundary loops, genus) from the meshes' README.
const TABLE: &[(&str, usize, usize, usize, i64)] = &[
    ("survey_bar.off", 6084, 12106, 1, 0),
    ("survey_cylinder.off", 4802, 9600, 0, 0),
    ("survey_bumpy_plane.off", 40401, 80000, 1, 0),
    ("survey_cactus.off", 5261, 10518, 0, 0),
    ("bar_722.off", 722, 1440, 0, 0),
    ("cylinder_tube_600.off", 600, 1160, 2, 0),
    ("bumpy_plane_441.off", 441, 800, 1, 0),
    ("flag_grid_441.off", 441, 800, 1, 0),
    ("libigl_grid_145.off", 145, 256, 1, 0),
    ("hand_1502.obj", 1502, 3000, 0, 0),
    ("eth_hand_14k.off", 14347, 28690, 0, 0),
    ("torus_288.off", 288, 576, 0, 1),
    ("dino_14070.off", 14070, 28136, 0, 0),
    ("dino_6013.obj", 6013, 12022, 0, 0),
    ("camel_9770.off", 9770, 19536, 0, 0),
    ("armadillo_43k.obj", 43243, 86482, 0, 0),
    ("nefertiti_50k.obj", 49971, 99938, 0, 0),
    ("feline_50k.off", 49864, 99732, 0, 2),
    ("igea_134k.ply", 134345, 268686, 0, 0),
];

#[test]
fn every_shared_mesh_loads_validates_and_matches_the_readme() {
    let Some(dir) = meshes_dir() else { return };
    for &(file, v, f, loops, genus) in TABLE {
        let path = dir.join(file);
        if !path.exists() {
            println!("skipping: {} not found", path.display());
            continue;
        }
        let m = read_path(&path).unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(
            (
                m.num_vertices(),
                m.num_triangles(),
                m.topology().boundary_loops().len(),
                m.genus()
            ),
            (v, f, loops, genus),
            "{file}"
        );
        assert_eq!(m.topology().num_components(), 1, "{file}");
        assert!(m.unreferenced_vertices().is_empty(), "{file}");
    }
    // every mesh in the folder is in the table
    for e in std::fs::read_dir(&dir).unwrap() {
        let name = e.unwrap().file_name().into_string().unwrap();
        if [".off", ".obj", ".ply", ".stl"]
            .iter()
            .any(|x| name.ends_with(x))
        {
            assert!(TABLE.iter().any(|t| t.0 == name), "{name} not in the table");
        }
    }
}

#[test]
fn survey_selections_and_transforms() {
    let Some(dir) = meshes_dir() else { return };
    // (name, fixed, handle) counts where the README states them
    for (name, fixed, handle) in [
        ("bar", Some(382), Some(580)),
        ("cylinder", Some(241), Some(241)),
        ("bumpy_plane", None, None),
        ("cactus", None, None),
    ] {
        let base = dir.join(format!("survey_{name}"));
        if !base.with_extension("sel").exists() {
            println!("skipping: survey_{name} not found");
            continue;
        }
        let m = read_path(&base.with_extension("off")).unwrap();
        let sel = read_sel(&base.with_extension("sel")).unwrap();
        sel.check_len(m.num_vertices()).unwrap();
        let h = sel.indices(VertexStatus::Handle);
        assert!(
            !h.is_empty() && !sel.indices(VertexStatus::Fixed).is_empty(),
            "{name}"
        );
        if let Some(n) = fixed {
            assert_eq!(sel.indices(VertexStatus::Fixed).len(), n, "{name}");
        }
        if let Some(n) = handle {
            assert_eq!(h.len(), n, "{name}");
        }
        let def = read_def(&base.with_extension("def")).unwrap();
        // the linear part is a rotation: orthonormal with determinant +1
        let r = def.matrix;
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                assert!((d - if i == j { 1.0 } else { 0.0 }).abs() < 1e-4, "{name}");
            }
        }
        if name == "bar" {
            // 135° about z, applied to the handle: z kept, distance to the axis kept
            let angle = r[1][0].atan2(r[0][0]).to_degrees();
            assert!((angle - 135.0).abs() < 1e-3, "bar angle {angle}");
            for &i in &h {
                let p = m.positions()[i as usize];
                let q = def.apply(p);
                assert!((q[2] - p[2]).abs() < 1e-9);
                let rp = (p[0] * p[0] + p[1] * p[1]).sqrt();
                let rq = (q[0] * q[0] + q[1] * q[1]).sqrt();
                assert!((rp - rq).abs() < 1e-4 * (1.0 + rp));
            }
        }
        if name == "cylinder" {
            // 120° about y; the translation sits in the last column (column-vector convention)
            assert!((r[0][0] + 0.5).abs() < 1e-6 && (r[2][0] - 0.866025).abs() < 1e-6);
            assert!(r[0][3] != 0.0 && r[3][0] == 0.0);
        }
    }
}
