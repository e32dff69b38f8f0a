//! Fitting one rigid motion per joint to a solved pose, under the asset's
//! own skin weights and linear blend skinning.
//!
//! **Model.** Joint `j` moves bind space by `M_j(x) = R_j (x − h_j) + h'_j`:
//! a rotation `R_j` about its bind head `h_j`, which goes to `h'_j`. Bone
//! lengths are kept: a joint with a parent joint `p` has its head carried
//! by the parent, `h'_j = M_p(h_j)`; only the heads of root joints are
//! free. The skinned position of asset vertex `i` is
//! `f_i = Σ_j w_ij M_j(v_i)` (linear blend skinning, `v_i` its bind
//! position) and the fit minimises `E = Σ_i |p_i − f_i|²` over the `R_j`
//! and the roots' `h'_j`, `p_i` the solved pose.
//!
//! **Alternating Procrustes** (Le and Deng 2012, "Smooth Skinning
//! Decomposition with Rigid Bones", §4.2; James and Twigg 2005, "Skinning
//! Mesh Animations", fit the same per-bone problem): the joints are
//! updated one at a time, parents first, each to its exact minimiser with
//! the others held. With the others held, `f_i` is affine in joint `j`'s
//! unknowns: `f_i = c_i + R_j a_i + s_i h'_j` with
//! `a_i = w_ij (v_i − h_j) + Σ_c W_ic (h_c − h_j)` (over `j`'s children
//! `c`, `W_ic` the weight of vertex `i` on `c`'s subtree: rotating `j`
//! swings its descendants' heads) and `s_i` the weight of `i` on `j`'s
//! subtree. So the update is [`procrustes::rotation`] of
//! `Σ (b_i − s_i h'_j) a_iᵀ` about the carried head, or for a root
//! [`procrustes::rigid`], with `b_i = p_i − c_i`. Each update lowers `E`
//! or keeps it, so sweeps stop when `E` stops falling
//! ([`FitOptions::tolerance`]) or after [`FitOptions::max_sweeps`].
//! A joint no vertex of its subtree is weighted to follows its parent
//! (its local rotation stays at rest). Every vertex counts the same.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::procrustes;
use super::skeleton::Skeleton;
use crate::mesh::Point;

/// Stopping rules of [`fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// At most this many sweeps over the joints.
    pub max_sweeps: usize,
    /// Stop when a sweep lowers `E` by less than this fraction of it.
    pub tolerance: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            max_sweeps: 200,
            tolerance: 1e-10,
        }
    }
}

/// How far the fitted skinning is from the solved pose, per asset vertex
/// `|p_i − f_i|`, as fractions of the rest pose's bounding-box diagonal.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Residual {
    /// The largest.
    pub max: f64,
    /// The mean.
    pub mean: f64,
}

/// The motions of the joints: rotation and posed head each.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Motions {
    /// `R_j`.
    pub rotations: Vec<Matrix3<f64>>,
    /// `h'_j`.
    pub heads: Vec<Vector3<f64>>,
    /// Sweeps taken.
    pub sweeps: usize,
}

impl Motions {
    /// `M_j(x)`.
    pub fn apply(&self, sk: &Skeleton, j: usize, x: &Vector3<f64>) -> Vector3<f64> {
        self.rotations[j] * (x - sk.joints[j].head) + self.heads[j]
    }

    /// Places the heads of non-root joints by their parents
    /// (`h'_j = M_p(h_j)`), parents first.
    fn carry_heads(&mut self, sk: &Skeleton) {
        for &j in &sk.order {
            if let Some(p) = sk.joints[j].parent {
                self.heads[j] = self.apply(sk, p, &sk.joints[j].head);
            }
        }
    }

    /// `f_i = Σ_j w_ij M_j(v_i)`.
    pub fn skinned(&self, sk: &Skeleton, i: usize, v: &Vector3<f64>) -> Vector3<f64> {
        sk.skin.influences[i]
            .iter()
            .map(|&(j, w)| self.apply(sk, j as usize, v) * w)
            .sum()
    }
}

/// One vertex's share in a joint's update: its weight on a joint of the
/// subtree, reached through `child` (`u32::MAX`: the joint itself).
#[derive(Debug, Clone, Copy)]
struct Term {
    vertex: u32,
    weight: f64,
    child: u32,
}

/// Per joint, the terms of every vertex weighted to its subtree, grouped
/// by vertex.
fn terms(sk: &Skeleton) -> Vec<Vec<Term>> {
    let mut out = vec![Vec::new(); sk.joints.len()];
    for (i, inf) in sk.skin.influences.iter().enumerate() {
        for &(k, weight) in inf {
            let (mut j, mut child) = (k, u32::MAX);
            // (the hierarchy is acyclic: Skeleton checked it)
            loop {
                out[j as usize].push(Term {
                    vertex: i as u32,
                    weight,
                    child,
                });
                match sk.joints[j as usize].parent {
                    Some(p) => (child, j) = (j, p as u32),
                    None => break,
                }
            }
        }
    }
    for t in &mut out {
        t.sort_by_key(|t| t.vertex);
    }
    out
}

/// The fitted motions of `sk`'s joints taking the bind pose `rest` to
/// `pose` (both per asset vertex, bind space); module documentation.
pub(super) fn fit_motions(
    sk: &Skeleton,
    rest: &[Point],
    pose: &[Point],
    opts: &FitOptions,
) -> Motions {
    let n = sk.joints.len();
    let mut m = Motions {
        rotations: vec![Matrix3::identity(); n],
        heads: sk.joints.iter().map(|j| j.head).collect(),
        sweeps: 0,
    };
    let v: Vec<Vector3<f64>> = rest.iter().map(|p| Vector3::from(*p)).collect();
    let p: Vec<Vector3<f64>> = pose.iter().map(|p| Vector3::from(*p)).collect();
    let terms = terms(sk);
    let mut f: Vec<Vector3<f64>> = (0..v.len()).map(|i| m.skinned(sk, i, &v[i])).collect();
    let energy =
        |f: &[Vector3<f64>]| -> f64 { f.iter().zip(&p).map(|(f, p)| (p - f).norm_squared()).sum() };
    let mut e = energy(&f);
    let mut scratch: Vec<(usize, Vector3<f64>, f64)> = Vec::new();
    while m.sweeps < opts.max_sweeps && e > 0.0 {
        m.sweeps += 1;
        for &j in &sk.order {
            let parent = sk.joints[j].parent;
            if terms[j].is_empty() {
                m.rotations[j] = parent.map_or(Matrix3::identity(), |q| m.rotations[q]);
                m.carry_heads(sk);
                continue;
            }
            // a_i and s_i per vertex of the subtree
            scratch.clear();
            let h = sk.joints[j].head;
            for t in &terms[j] {
                let i = t.vertex as usize;
                let arm = if t.child == u32::MAX {
                    v[i] - h
                } else {
                    sk.joints[t.child as usize].head - h
                };
                match scratch.last_mut() {
                    Some(last) if last.0 == i => {
                        last.1 += arm * t.weight;
                        last.2 += t.weight;
                    }
                    _ => scratch.push((i, arm * t.weight, t.weight)),
                }
            }
            let (r0, h0) = (m.rotations[j], m.heads[j]);
            let b = |&(i, a, s): &(usize, Vector3<f64>, f64)| p[i] - f[i] + r0 * a + h0 * s;
            match parent {
                Some(_) => {
                    let mut cov = Matrix3::zeros();
                    for x in &scratch {
                        cov += (b(x) - h0 * x.2) * x.1.transpose();
                    }
                    m.rotations[j] = procrustes::rotation(&cov, &r0);
                }
                None => {
                    let pts = scratch.iter().map(|x| (x.1, b(x), x.2));
                    if let Some((r, t)) = procrustes::rigid(pts, &r0) {
                        m.rotations[j] = r;
                        m.heads[j] = t;
                    }
                }
            }
            m.carry_heads(sk);
            for x in &scratch {
                f[x.0] = m.skinned(sk, x.0, &v[x.0]);
            }
        }
        let next = energy(&f);
        let done = e - next <= opts.tolerance * e;
        e = next;
        if done {
            break;
        }
    }
    m
}
