//! The elastic iteration's memory ([`State`]), which a [`Deformer`]
//! holds and `local_global.rs` works on: a leaf below both, so that the
//! deformer's file names no file that names it back.
//!
//! [`Deformer`]: super::Deformer

use faer::dyn_stack::MemBuffer;
use nalgebra::UnitQuaternion;

use super::newton_state::NewtonState;
use crate::deform::anderson::Anderson;
use crate::mesh::{Point, Real};

/// The elastic iteration's memory, sized once per constraint set.
#[derive(Default)]
pub(super) struct State {
    /// `R(Y)` of the current pose (and the candidate's, while tried).
    pub(super) rot: Vec<UnitQuaternion<Real>>,
    pub(super) rot_try: Vec<UnitQuaternion<Real>>,
    /// Each vertex's turn `exp(w_i)` while rotations turn by a field of
    /// rotation vectors (scratch of `Deformer::turn_rotations`).
    pub(super) turns: Vec<UnitQuaternion<Real>>,
    /// The area projections `P_t` (and the candidate's).
    pub(super) proj: Vec<[Real; 6]>,
    pub(super) proj_try: Vec<[Real; 6]>,
    /// `L Y`.
    pub(super) ly: Vec<Point>,
    /// `R_i δ_i` and `R_i` as matrices (scratch), and the residual
    /// `g(R) − Q Y`, `#V`.
    pub(super) t: Vec<Point>,
    pub(super) rm: Vec<[Real; 4]>,
    pub(super) res: Vec<Point>,
    /// Right-hand side / update, column-major `|U| × 3`.
    pub(super) rhs: Vec<Real>,
    /// Flat `3|U|` current iterate, Anderson candidate and `Q_UU Δ`.
    pub(super) x_flat: Vec<Real>,
    pub(super) cand: Vec<Real>,
    pub(super) mf: Vec<Real>,
    /// How the next sequence starts.
    pub(super) start: Start,
    pub(super) anderson: Anderson,
    pub(super) mem: Option<MemBuffer>,
    pub(super) sized_for: (u64, usize),
    /// The energy of the current pose and the factor it was computed with,
    /// when the next call may continue the sequence.
    pub(super) chain: Option<(u64, Real)>,
    /// The handles' target rotations the current pose was solved for
    /// (empty from the rest pose): a new target turns the rotations by
    /// the change ([`Deformer::propagate_rotation_change`]).
    ///
    /// [`Deformer::propagate_rotation_change`]: super::Deformer::propagate_rotation_change
    pub(super) handle_rot: Vec<UnitQuaternion<Real>>,
    /// Each handle's harmonic weight `φ_h` over the vertices (`#V` per
    /// handle, 0 off the free vertices), for the factor with this id.
    pub(super) harmonic: Option<(u64, Vec<Vec<Real>>)>,
    /// A linear term `−2⟨s, Y⟩` added to the objective (`#V`, empty for
    /// none): the coarse problem of a correction (`solver/multilevel.rs`).
    pub(super) linear: Vec<Point>,
    /// Whether this sequence still tries coarse corrections, the fine
    /// iterations since the last one, and the energy after it.
    pub(super) corrections: bool,
    pub(super) since_correction: usize,
    /// Whether this sequence corrects on the hierarchy where the mesh has
    /// a Newton level (`solver/multilevel.rs`): it started from the rest
    /// pose, or a correction on the Newton level gained nothing.
    pub(super) on_hierarchy: bool,
    pub(super) e_mark: Real,
    /// The sequence's last update (largest vertex move) and how many
    /// iterations in a row it has grown ([`Deformer::drift_limit`]).
    ///
    /// [`Deformer::drift_limit`]: super::Deformer::drift_limit
    pub(super) last_update: Real,
    pub(super) grew: usize,
    /// The coarsest level's Newton iteration (`solver/newton.rs`).
    pub(super) newton: NewtonState,
    /// Iterations of the current sequence so far (over its calls), the
    /// updates of its last iterations, and whether it has switched to
    /// Newton steps (`Deformer::takes_newton_step`).
    pub(super) sequence_iterations: usize,
    pub(super) recent_updates: std::collections::VecDeque<Real>,
    pub(super) newton_now: bool,
    /// Newton candidates of the current sequence that lowered nothing in
    /// a row; at [`NEWTON_GIVE_UP`] the sequence takes no more Newton
    /// steps.
    ///
    /// [`NEWTON_GIVE_UP`]: super::local_global::NEWTON_GIVE_UP
    pub(super) newton_failures: usize,
}

/// How a new iteration sequence gets its first rotations.
#[derive(Default, Clone, Copy, PartialEq, Eq)]
pub(super) enum Start {
    /// The pose is the rest pose: rotations from a coarse solve
    /// ([`Deformer::coarse_start`]) or, without one, propagated from the
    /// handles' rotations ([`Deformer::propagate_rotations`]).
    ///
    /// [`Deformer::coarse_start`]: super::Deformer::coarse_start
    /// [`Deformer::propagate_rotations`]: super::Deformer::propagate_rotations
    #[default]
    Rest,
    /// The pose or the weights were replaced: fit the rotations to it.
    Refit,
    /// The rotations are the current pose's: keep them.
    Warm,
}
