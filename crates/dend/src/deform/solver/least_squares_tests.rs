//! The matrix-free residual and right-hand side of eq. (24) against the
//! assembled `J`.

use super::*;
use crate::deform::energy::Energy;
use crate::deform::factor::tests::{edit, grid, pseudo_random};
use crate::deform::params::Params;
use crate::deform::rest::Rest;
use crate::deform::{Factor, SolveOptions, SolverChoice};
use std::sync::Arc;

/// The matrix-free residual and `J_Uᵀ r` (stacked.rs, chunked on the
/// rayon pool above `PARALLEL_MIN_ROWS`) against products with `J`
/// assembled explicitly from `energy_matrix` (`A` by sparse products):
/// for every energy, with the linear detail term the whole residual
/// `r = [W (A X − A Y)_R; √λ2 W (δ − L Y)_R]`, and in the default mode
/// `rhs = J_Uᵀ r` and `f = |r|²`.
#[test]
fn matrix_free_residual_and_rhs_match_assembled_j() {
    let k = 95;
    let mesh = grid(k);
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let ops = &rest.ops;
    let c = edit(&mesh, k);
    let n = mesh.num_vertices();
    let noise = pseudo_random(3 * n);
    for energy in [
        Energy::Membrane,
        Energy::ThinPlate,
        Energy::Combined { ks: 0.7, kb: 1.3 },
        Energy::TotalCurvature,
        Energy::TotalCurvaturePaper,
    ] {
        for detail in [DetailTerm::Linear, DetailTerm::Nonlinear] {
            let params = Params {
                formulation: crate::deform::FormulationParams::LeastSquares(Default::default()),
                energy,
                detail,
                lambda2: 0.3,
                ..Params::default()
            };
            let opts = SolveOptions {
                solver: SolverChoice::Direct,
                ..SolveOptions::default()
            };
            let factor = Factor::build_with(&rest, &params, &c, &opts).unwrap();
            let sys = &factor.sys;
            let (nr, nu) = (sys.rows.len(), sys.unknowns.len());
            let nrows = 2 * nr;
            assert!(nr >= PARALLEL_MIN_ROWS && nu >= PARALLEL_MIN_ROWS);
            let a = crate::deform::energy_matrix(ops, energy);
            // J row by row: (column, value) lists
            let j_rows: Vec<Vec<(usize, f64)>> = (0..nrows)
                .map(|row| {
                    let (m, k, s) = if row < nr {
                        (&a, row, 1.0)
                    } else {
                        (&ops.l, row - nr, sys.sqrt_lambda2)
                    };
                    let w = sys.row_weight[k] * s;
                    m.outer_view(sys.rows[k] as usize)
                        .map(|r| r.iter().map(|(c, &v)| (c, w * v)).collect())
                        .unwrap_or_default()
                })
                .collect();
            let mut d = Deformer::new(rest.clone(), params);
            d.prepare(&factor);
            for (v, y) in d.y.iter_mut().enumerate() {
                let p = ops.positions[v];
                *y = [0, 1, 2].map(|i| p[i] + 0.1 * noise[3 * v + i]);
            }
            let f = d.evaluate(&factor);
            d.right_hand_side(&factor);
            let (r, rhs, y) = (&d.scratch.r, &d.scratch.rhs, &d.y);
            let obj: f64 = r[..3 * nrows].iter().map(|v| v * v).sum();
            assert!((f - obj).abs() <= 1e-12 * f, "{energy:?} {detail:?}");
            let jy = |row: usize, i: usize| -> f64 {
                j_rows[row].iter().map(|&(c, v)| v * y[c][i]).sum()
            };
            let jx = |row: usize, i: usize| -> f64 {
                j_rows[row]
                    .iter()
                    .map(|&(c, v)| v * ops.positions[c][i])
                    .sum()
            };
            if detail == DetailTerm::Linear {
                // b = J X (A X and δ = L X): r = J (X - Y)
                let scale = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for row in 0..nrows {
                    for i in 0..3 {
                        let e = jx(row, i) - jy(row, i);
                        let got = r[i * nrows + row];
                        assert!(
                            (got - e).abs() <= 1e-9 * scale,
                            "{energy:?}: residual row {row}.{i}: {got} vs {e}"
                        );
                    }
                }
            }
            // J_Uᵀ r, column by column of J
            let mut expected = vec![0.0; 3 * nu];
            for (row, jr) in j_rows.iter().enumerate() {
                for &(col, v) in jr {
                    let u = sys.col_of[col];
                    if u != u32::MAX {
                        for i in 0..3 {
                            expected[i * nu + u as usize] += v * r[i * nrows + row];
                        }
                    }
                }
            }
            let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for (q, (&got, &e)) in rhs.iter().zip(&expected).enumerate() {
                assert!(
                    (got - e).abs() <= 1e-9 * scale,
                    "{energy:?} {detail:?}: rhs {q}: {got} vs {e}"
                );
            }
        }
    }
}
