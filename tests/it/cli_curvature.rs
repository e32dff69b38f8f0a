//! `dend curvature`: the CSV equals the library values in mesh units.

use std::process::Command;

use dend::operators::Operators;
use dend_testkit::*;

fn dend() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dend"))
}

#[test]
fn curvature_csv_matches_library_on_a_sphere() {
    let r = 2.5;
    let m = icosphere(3, r);
    let dir = tempfile::tempdir().unwrap();
    let (inp, out) = (dir.path().join("s.off"), dir.path().join("c.csv"));
    write_mesh(&m, &inp);
    let st = dend()
        .arg("curvature")
        .arg(&inp)
        .arg("-o")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("index,area,mean_curvature,gaussian_curvature,g")
    );
    let op = Operators::new(&m);
    let s = op.scale;
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), m.num_vertices());
    let mut total_area = 0.0;
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row[0], i as f64);
        let want = [
            op.area[i] * s * s,
            op.mean_curvature[i] / s,
            op.gaussian_curvature[i] / (s * s),
            op.g[i] / (s * s),
        ];
        for k in 0..4 {
            assert!(
                (row[k + 1] - want[k]).abs() <= 1e-15 * want[k].abs(),
                "row {i} col {k}: {} vs {}",
                row[k + 1],
                want[k]
            );
        }
        // mesh units and sign convention: H ≈ +1/r, K ≈ 1/r² (outward normals)
        assert!((row[2] * r - 1.0).abs() < 0.05, "H {} on r = {r}", row[2]);
        assert!((row[3] * r * r - 1.0).abs() < 0.2, "K {}", row[3]);
        total_area += row[1];
    }
    let sphere = 4.0 * std::f64::consts::PI * r * r;
    assert!((total_area - sphere).abs() < 0.02 * sphere);
}

#[test]
fn curvature_reports_bad_input_with_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("c.csv");
    let missing = dir.path().join("missing.off");
    let bad = dir.path().join("bad.off");
    std::fs::write(&bad, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").unwrap();
    for inp in [&missing, &bad] {
        let st = dend()
            .arg("curvature")
            .arg(inp)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert_eq!(st.status.code(), Some(2));
        let err = String::from_utf8_lossy(&st.stderr);
        assert!(err.contains("error:"), "{err}");
    }
}
