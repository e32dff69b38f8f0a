//! A generated OBJ with named groups, for the tests of constraints by group
//! (`tests/it/asset_groups.rs`, `tests/it/server_gltf.rs`).

/// Columns around the tube.
pub const AROUND: usize = 12;
/// Rings along z.
pub const RINGS: usize = 8;

/// A tube of `AROUND` columns × `RINGS` rings (ring `k` at `z = k`), with a UV
/// seam (column `AROUND` repeats column 0's positions with `u = 1`), whose
/// quads are in `g base` (band 0), `g mid` (bands 1..RINGS-3) and
/// `g tip end` (the last band, in both `tip` and `end`), all under `o tube`.
pub fn banded_tube_obj() -> String {
    let mut s = String::from("# banded tube\nmtllib tube.mtl\no tube\n");
    for k in 0..RINGS {
        for c in 0..=AROUND {
            let a = std::f64::consts::TAU * (c % AROUND) as f64 / AROUND as f64;
            s += &format!("v {} {} {k}\n", a.cos(), a.sin());
        }
    }
    for k in 0..RINGS {
        for c in 0..=AROUND {
            s += &format!(
                "vt {} {}\n",
                c as f64 / AROUND as f64,
                k as f64 / (RINGS - 1) as f64
            );
        }
    }
    let id = |k: usize, c: usize| k * (AROUND + 1) + c + 1;
    for band in 0..RINGS - 1 {
        if band == 0 {
            s += "g base\nusemtl red\n";
        } else if band == 1 {
            s += "g mid\n";
        } else if band == RINGS - 2 {
            s += "g tip end\n";
        }
        for c in 0..AROUND {
            let q = [
                id(band, c),
                id(band, c + 1),
                id(band + 1, c + 1),
                id(band + 1, c),
            ];
            s += &format!(
                "f {}/{} {}/{} {}/{} {}/{}\n",
                q[0], q[0], q[1], q[1], q[2], q[2], q[3], q[3]
            );
        }
    }
    s
}
