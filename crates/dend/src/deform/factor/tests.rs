//! Tests of the factor's solve back ends against each other, on a
//! deformation's own normal matrix (moved here from the linear-algebra
//! modules, which cannot see `Rest` or `Factor`), and the helpers the other
//! deform tests share.

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::MatMut;

use crate::deform::{
    Constraints, Deformer, Factor, FactorPrecision, FillOrdering, Params, Rest, RigidTransform,
    SolveOptions, SolverChoice,
};
use crate::mesh::Mesh;

/// A wavy `k × k` grid in the xy plane.
pub(in crate::deform) fn grid(k: usize) -> Mesh {
    let mut p = Vec::new();
    for r in 0..k {
        for c in 0..k {
            let (x, y) = (c as f64, r as f64 * 0.93);
            p.push([x, y, 0.3 * (0.7 * x).sin() * (0.5 * y).cos()]);
        }
    }
    let mut t = Vec::new();
    let k = k as u32;
    for r in 0..k - 1 {
        for c in 0..k - 1 {
            let v = r * k + c;
            t.push([v, v + 1, v + k + 1]);
            t.push([v, v + k + 1, v + k]);
        }
    }
    Mesh::new(p, t).unwrap()
}

pub(in crate::deform) fn edit(mesh: &Mesh, k: usize) -> Constraints {
    let fixed: Vec<u32> = (0..k as u32).map(|r| r * k as u32).collect();
    let handle: Vec<u32> = (0..k as u32).map(|r| r * k as u32 + k as u32 - 1).collect();
    let mut t = RigidTransform::identity([0.0; 3]);
    t.translation = [0.0, 0.0, 3.0];
    Constraints::new(mesh, fixed, vec![("h".into(), handle, Some(t))]).unwrap()
}

fn options(solver: SolverChoice, cg_tol: f64) -> SolveOptions {
    SolveOptions {
        solver,
        cg_tol,
        ..SolveOptions::default()
    }
}

/// A fixed pseudo-random right-hand side of `len` values in [-0.5, 0.5).
pub(in crate::deform) fn pseudo_random(len: usize) -> Vec<f64> {
    (0..len)
        .map(|i| ((i * 7919 % 1013) as f64 / 1013.0) - 0.5)
        .collect()
}

/// Solves `M X = B` with `f` for a fixed pseudo-random `B` (`n × 3`).
pub(in crate::deform) fn solve(f: &Factor, b: &[f64]) -> Vec<f64> {
    let n = f.num_unknowns();
    let mut x = b.to_vec();
    let mut mem = MemBuffer::new(f.solve_scratch(3));
    f.solve_in_place(
        MatMut::from_column_major_slice_mut(&mut x, n, 3),
        MemStack::new(&mut mem),
    );
    x
}

pub(in crate::deform) fn residual(f: &Factor, x: &[f64], b: &[f64]) -> f64 {
    let n = f.num_unknowns();
    let mut worst: f64 = 0.0;
    for c in 0..3 {
        let xc = &x[c * n..(c + 1) * n];
        let bc = &b[c * n..(c + 1) * n];
        let mx: Vec<f64> = f
            .sys
            .m
            .outer_iterator()
            .map(|row| row.iter().map(|(j, v)| v * xc[j]).sum())
            .collect();
        let r: f64 = mx.iter().zip(bc).map(|(a, b)| (a - b).powi(2)).sum();
        let bn: f64 = bc.iter().map(|v| v * v).sum();
        worst = worst.max((r / bn).sqrt());
    }
    worst
}

#[test]
fn cg_and_cholesky_agree_to_the_cg_tolerance() {
    let k = 14;
    let mesh = grid(k);
    let rest = Rest::new(mesh.clone()).unwrap();
    let c = edit(&mesh, k);
    let params = Params {
        formulation: crate::deform::FormulationParams::LeastSquares(Default::default()),
        ..Params::default()
    };
    let direct =
        Factor::build_with(&rest, &params, &c, &options(SolverChoice::Direct, 1e-4)).unwrap();
    assert!(!direct.uses_cg() && direct.factor_nnz() > 0);
    let n = direct.num_unknowns();
    let b = pseudo_random(3 * n);
    let x_chol = solve(&direct, &b);
    assert!(residual(&direct, &x_chol, &b) < 1e-9);
    for tol in [1e-4, 1e-10] {
        let cg = Factor::build_with(&rest, &params, &c, &options(SolverChoice::Cg, tol)).unwrap();
        assert!(cg.uses_cg() && cg.factor_nnz() == 0);
        let x_cg = solve(&cg, &b);
        assert!(cg.cg_iterations() > 0);
        // CG's stopping test, checked independently with M.
        let res = residual(&cg, &x_cg, &b);
        assert!(res <= tol * 1.01, "tol {tol}: residual {res}");
        // The tight solve agrees with Cholesky to well below the scale of x.
        if tol < 1e-8 {
            let scale = x_chol.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = x_chol
                .iter()
                .zip(&x_cg)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(diff < 1e-5 * scale, "diff {diff} scale {scale}");
        }
    }
}

#[test]
fn over_a_tiny_budget_the_mesh_still_deforms_by_cg() {
    let k = 12;
    let mesh = grid(k);
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = edit(&mesh, k);
    let params = Params {
        formulation: crate::deform::FormulationParams::LeastSquares(Default::default()),
        ..Params::default()
    };
    let tiny = SolveOptions {
        factor_budget_bytes: 1,
        cg_tol: 1e-8,
        ..SolveOptions::default()
    };
    let auto = Factor::build_with(&rest, &params, &c, &tiny).unwrap();
    assert!(auto.uses_cg());
    let direct = Factor::build(&rest, &params, &c).unwrap();
    assert!(!direct.uses_cg());
    let mut d_cg = Deformer::new(rest.clone(), params);
    let mut d_dir = Deformer::new(rest.clone(), params);
    let r_cg = d_cg.step(&auto, &c, 100).unwrap();
    let r_dir = d_dir.step(&direct, &c, 100).unwrap();
    assert!(r_cg.converged && !r_cg.diverged, "{r_cg:?}");
    // The handle reached its target and the free vertices moved.
    let moved = d_cg
        .pose()
        .iter()
        .zip(mesh.positions())
        .filter(|(a, b)| (a[2] - b[2]).abs() > 0.1)
        .count();
    assert!(moved > k * k / 3, "only {moved} vertices moved");
    let h = k - 1;
    assert!((d_cg.pose()[h][2] - mesh.positions()[h][2] - 3.0).abs() < 1e-9);
    // Same pose as the direct solver, to the iteration tolerance.
    let diff = d_cg
        .pose()
        .iter()
        .zip(d_dir.pose())
        .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max);
    assert!(
        diff < 0.05 * mesh.mean_edge_length(),
        "diff {diff}; {r_dir:?}"
    );
}

#[test]
fn a_single_precision_factor_halves_the_values_and_keeps_the_deformation() {
    let k = 40;
    let mesh = grid(k);
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = edit(&mesh, k);
    let params = Params {
        formulation: crate::deform::FormulationParams::LeastSquares(Default::default()),
        ..Params::default()
    };
    let build = |precision| {
        let opts = SolveOptions {
            solver: SolverChoice::Direct,
            precision,
            ..SolveOptions::default()
        };
        Factor::build_with(&rest, &params, &c, &opts).unwrap()
    };
    let (f64_, f32_) = (
        build(FactorPrecision::Double),
        build(FactorPrecision::Single),
    );
    assert!(f32_.is_supernodal());
    assert_eq!(f32_.factor_nnz(), f64_.factor_nnz());
    // values 8 -> 4 bytes; the row indices stay
    assert!(f32_.factor_bytes() < f64_.factor_bytes());
    assert!(f64_.factor_bytes() - f32_.factor_bytes() == 4 * f64_.factor_nnz());
    // the budget check's estimate is what the built factor holds
    for (f, p) in [
        (&f64_, FactorPrecision::Double),
        (&f32_, FactorPrecision::Single),
    ] {
        let est = super::backend::estimated_factor_bytes(f.symbolic().unwrap(), p);
        assert_eq!(est, f.factor_bytes());
    }
    let n = f64_.num_unknowns();
    let b = pseudo_random(3 * n);
    let (x64, x32) = (solve(&f64_, &b), solve(&f32_, &b));
    assert!(residual(&f64_, &x64, &b) < 1e-9);
    // the error the rounding adds: small, but not zero
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let err: Vec<f64> = x64.iter().zip(&x32).map(|(a, b)| a - b).collect();
    let rel = norm(&err) / norm(&x64);
    assert!(
        rel > 0.0 && rel < 1e-3,
        "single-precision relative error {rel}"
    );
    // the fixed point does not depend on the factor's precision
    let pose = |f: &Factor| {
        let mut d = Deformer::new(rest.clone(), params);
        let r = d.step(f, &c, 200).unwrap();
        assert!(r.converged, "{r:?}");
        d.pose().to_vec()
    };
    let (p64, p32) = (pose(&f64_), pose(&f32_));
    let diff = p64
        .iter()
        .zip(&p32)
        .flat_map(|(a, b)| (0..3).map(move |i| (a[i] - b[i]).abs()))
        .fold(0.0f64, f64::max);
    assert!(diff < 1e-3 * mesh.diagonal(), "poses differ by {diff}");
}

#[test]
fn both_orderings_factor_and_solve_the_same_system() {
    // large enough for a supernodal factor, so the solves run through
    // trisolve; the solution is checked against M itself
    let k = 40;
    let mesh = grid(k);
    let rest = Rest::new(mesh.clone()).unwrap();
    let c = edit(&mesh, k);
    let params = Params {
        formulation: crate::deform::FormulationParams::LeastSquares(Default::default()),
        ..Params::default()
    };
    let build = |ordering| {
        let opts = SolveOptions {
            solver: SolverChoice::Direct,
            ordering,
            ..SolveOptions::default()
        };
        Factor::build_with(&rest, &params, &c, &opts).unwrap()
    };
    let (amd, nd) = (
        build(FillOrdering::Amd),
        build(FillOrdering::NestedDissection),
    );
    assert!(amd.is_supernodal() && nd.is_supernodal());
    let n = amd.num_unknowns();
    let b = pseudo_random(3 * n);
    let (xa, xn) = (solve(&amd, &b), solve(&nd, &b));
    assert!(residual(&amd, &xa, &b) < 1e-9);
    assert!(residual(&nd, &xn, &b) < 1e-9);
    let scale = xa.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = xa
        .iter()
        .zip(&xn)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(diff < 1e-8 * scale, "diff {diff} scale {scale}");
}

/// Every top-level number of [`Params`] (a weight, a tolerance, a window),
/// changed by half its value on a rest state and a [`FactorCache`] that
/// have already served the defaults, gives the pose a fresh rest state
/// gives: a parameter that shapes the energy but is missing from the
/// cache keys (the factor's or the rest state's elastic operators) would
/// reuse the defaults' matrix and fail here. Found with `laplacian`, which
/// both keys lacked: two sessions on one mesh with different `k_L` shared
/// the first one's energy.
#[test]
fn every_numeric_parameter_reaches_the_cached_energy() {
    use crate::deform::FactorCache;
    let k = 9;
    let mesh = grid(k);
    let constraints = edit(&mesh, k);
    let base = Params::default();
    let pose = |rest: &Arc<Rest>, factor: &Factor, params: Params| {
        let mut d = Deformer::new(rest.clone(), params);
        d.step(factor, &constraints, 8).expect("step");
        d.pose().to_vec()
    };
    let serde_json::Value::Object(fields) = serde_json::to_value(base).expect("params to json")
    else {
        panic!("Params is not a JSON object");
    };
    let mut tried = Vec::new();
    for (name, value) in &fields {
        let Some(x) = value.as_f64() else { continue };
        let changed = if value.is_u64() {
            serde_json::json!(value.as_u64().unwrap_or(0) + 1)
        } else if x == 0.0 {
            serde_json::json!(0.5)
        } else {
            serde_json::json!(1.5 * x)
        };
        let mut v = serde_json::Value::Object(fields.clone());
        v[name] = changed;
        let params: Params = serde_json::from_value(v).expect("params from json");
        if params.validate().is_err() {
            continue;
        }
        tried.push(name.clone());
        let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
        let cache = FactorCache::new(1 << 30);
        let warm = cache.get_or_build(&rest, &base, &constraints).unwrap();
        let _ = pose(&rest, &warm, base);
        let cached = cache.get_or_build(&rest, &params, &constraints).unwrap();
        let fresh_rest = Arc::new(Rest::new(mesh.clone()).unwrap());
        let fresh = Factor::build(&fresh_rest, &params, &constraints).unwrap();
        let (a, b) = (
            pose(&rest, &cached, params),
            pose(&fresh_rest, &fresh, params),
        );
        let worst = a
            .iter()
            .zip(&b)
            .flat_map(|(p, q)| (0..3).map(move |c| (p[c] - q[c]).abs()))
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-9,
            "{name}: the cached pose is {worst:.3e} off the fresh one"
        );
    }
    for name in ["laplacian", "stretch", "bending", "area", "lambda2"] {
        assert!(
            tried.iter().any(|t| t == name),
            "{name} was not tried: {tried:?}"
        );
    }
}
