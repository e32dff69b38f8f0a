//! The paper formulations' iteration memory ([`Scratch`], [`Chain`]), which
//! a [`Deformer`] holds and `least_squares.rs` works on: a leaf below
//! both.
//!
//! [`Deformer`]: super::Deformer

use faer::dyn_stack::MemBuffer;
use nalgebra::UnitQuaternion;

use crate::deform::anderson::Anderson;
use crate::mesh::{Point, Real};

#[derive(Default)]
pub(super) struct Scratch {
    pub(super) rot: Vec<UnitQuaternion<Real>>,
    pub(super) tdelta: Vec<Point>,
    pub(super) lv: Vec<Point>,
    pub(super) dhat: Vec<Point>,
    /// `#V` buffers of the products with `L` (stacked.rs): `e` for the
    /// residual; `u`, `v`, `Lᵀ u` and the inner vector of `J_Uᵀ r`.
    pub(super) e: Vec<Point>,
    pub(super) gu: Vec<Point>,
    pub(super) gv: Vec<Point>,
    pub(super) glu: Vec<Point>,
    pub(super) gx: Vec<Point>,
    /// Residual `b - J Y`, column-major `2|R| × 3`.
    pub(super) r: Vec<Real>,
    /// Right-hand side / solution, column-major `|U| × 3`.
    pub(super) rhs: Vec<Real>,
    pub(super) y_prev: Vec<Point>,
    pub(super) best: Vec<Point>,
    /// The constrained vertices and their normalised targets, and the
    /// same targets in mesh units as given (`load_targets`).
    pub(super) targets: Vec<(u32, Point)>,
    pub(super) targets_given: Vec<Point>,
    /// Anderson history and flat `3|U|` buffers (current iterate, candidate).
    pub(super) anderson: Anderson,
    pub(super) x_flat: Vec<Real>,
    pub(super) cand: Vec<Real>,
    pub(super) mem: Option<MemBuffer>,
    pub(super) sized_for: (usize, usize),
    /// Set when `r` (and `rot`, `dhat`) hold the evaluation of the current
    /// pose `y`: the next step on unchanged targets continues this chain.
    pub(super) evaluated: Option<Chain>,
}

/// The state a step leaves for the next one on unchanged targets: the next
/// step starts without re-evaluating (a one-iteration settle frame costs one
/// evaluation, not two) and is safeguarded like the continuation of one long
/// step (`Scratch::best` still holds the chain's best pose).
#[derive(Clone, Copy)]
pub(super) struct Chain {
    /// The factor the evaluation was made with.
    pub(super) factor: u64,
    /// The objective at the current pose.
    pub(super) f: Real,
    /// Consecutive growing steps so far.
    pub(super) growing: usize,
    /// The best objective of the chain.
    pub(super) best_f: Real,
    /// The objective at the start of the chain.
    pub(super) f_start: Real,
    /// Anderson back-off: candidates still to skip, and the current skip length.
    pub(super) aa_skip: u32,
    pub(super) aa_backoff: u32,
}
