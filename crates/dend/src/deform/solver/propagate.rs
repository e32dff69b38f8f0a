//! Rotations spread from the handles over the free vertices by harmonic
//! weights: the first rotations of an edit from the rest pose (without a
//! coarse level) and the turn of a solved pose whose handles rotate
//! further (steps of an edit, rotating drags).

use faer::dyn_stack::MemStack;
use faer::MatMut;
use nalgebra::{UnitQuaternion, Vector3};

use super::Deformer;
use crate::deform::constraints::Constraints;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::mesh::Real;

impl Deformer {
    /// The rotations of a sequence that starts at the rest pose: with `w_h`
    /// the rotation vector (axis × angle) of handle `h`'s target and `φ_h`
    /// its harmonic weight ([`Deformer::harmonic_weights`]),
    /// `R_i = exp(Σ_h φ_h(i) w_h)`; the area targets follow
    /// (`P_t = R_{t0} F_t(X)`). Handles that do not rotate add nothing, so a
    /// pure translation keeps the identity.
    pub(super) fn propagate_rotations(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
    ) {
        for (i, q) in self.elastic.rot.iter_mut().enumerate() {
            if set.fit[i] {
                *q = UnitQuaternion::identity();
            }
        }
        let turns: Vec<(usize, Vector3<Real>)> = constraints
            .handles
            .iter()
            .enumerate()
            .map(|(k, h)| (k, h.target.rotation.scaled_axis()))
            .filter(|(_, w)| w.norm() > 1e-12)
            .collect();
        if !turns.is_empty() {
            let w = self.spread(factor, set, constraints, &turns);
            let st = &mut self.elastic;
            for (i, (q, w)) in st.rot.iter_mut().zip(&w).enumerate() {
                if set.fit[i] {
                    *q = UnitQuaternion::from_scaled_axis(*w);
                }
            }
        }
        let st = &mut self.elastic;
        el.rotated_rest_projections(&self.rest.ops.positions, &st.rot, &mut st.proj);
    }

    /// A sequence from a solved pose whose handle targets moved: each
    /// handle's change of rotation `ΔR_h = R_h^new (R_h^old)ᵀ` is spread
    /// like the first rotations of an edit ([`Deformer::propagate_rotations`]),
    /// `R_i ← exp(Σ_h φ_h(i) log ΔR_h) R_i`, and each area target turns
    /// with its triangle's first vertex (`P_t ← ΔR_{t0} P_t`). A twist
    /// applied in steps then starts each step from the turned pose instead
    /// of untwisting it from the old rotations; a pure translation changes
    /// nothing.
    pub(super) fn propagate_rotation_change(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
    ) {
        if self.elastic.handle_rot.len() != constraints.handles.len() {
            return;
        }
        let turns: Vec<(usize, Vector3<Real>)> = constraints
            .handles
            .iter()
            .zip(&self.elastic.handle_rot)
            .enumerate()
            .map(|(k, (h, old))| (k, (h.target.rotation * old.inverse()).scaled_axis()))
            .filter(|(_, w)| w.norm() > 1e-12)
            .collect();
        if turns.is_empty() {
            return;
        }
        let w = self.spread(factor, set, constraints, &turns);
        self.turn_rotations((el, set), &w);
    }

    /// Turns the rotations of the vertices with `set.fit` by the rotation
    /// vectors `w` (`R_i ← exp(w_i) R_i`) and each area target with its
    /// triangle's first vertex (`P_t ← exp(w_{t0}) P_t`).
    ///
    /// Each vertex's `exp(w_i)` is computed once and its area targets reuse
    /// it: computed again for every triangle it took 0.41 ms of a 5 ms
    /// camel_9770 iteration, in every drag's first step and every
    /// correction, against 0.25 ms now (one thread; on the rayon pool it
    /// took 0.30 ms, the pool's hand-offs costing more than they saved).
    /// The same quaternions as before, so the same poses.
    pub(super) fn turn_rotations(
        &mut self,
        (el, set): (&ElasticOps, &ElasticSet),
        w: &[Vector3<Real>],
    ) {
        let st = &mut self.elastic;
        st.turns.clear();
        st.turns
            .extend(w.iter().map(|w| UnitQuaternion::from_scaled_axis(*w)));
        for ((q, t), &fit) in st.rot.iter_mut().zip(&st.turns).zip(&set.fit) {
            if fit {
                *q = t * *q;
            }
        }
        for (v0, p) in el.area_first_vertices().zip(st.proj.iter_mut()) {
            let t = &st.turns[v0];
            let c0 = t * Vector3::new(p[0], p[1], p[2]);
            let c1 = t * Vector3::new(p[3], p[4], p[5]);
            *p = [c0[0], c0[1], c0[2], c1[0], c1[1], c1[2]];
        }
    }

    /// `Σ_h φ_h(i) w_h` per vertex for the handle rotation vectors `turns`
    /// (`(handle index, w_h)`), `φ_h` clamped to `[0, 1]`.
    fn spread(
        &mut self,
        factor: &Factor,
        set: &ElasticSet,
        constraints: &Constraints,
        turns: &[(usize, Vector3<Real>)],
    ) -> Vec<Vector3<Real>> {
        let n = self.y.len();
        self.harmonic_weights(factor, set, constraints);
        let phi = &self.elastic.harmonic.as_ref().expect("computed above").1;
        let mut w = vec![Vector3::<Real>::zeros(); n];
        for &(k, wh) in turns {
            for (wi, &p) in w.iter_mut().zip(&phi[k]) {
                *wi += wh * p;
            }
        }
        w
    }

    /// Computes (once per factor) each handle's harmonic weight `φ_h`:
    /// `Q_UU φ_h = −Q_UC 1_h` (1 on the handle, 0 on the other constrained
    /// vertices), solved with the factor three handles at a time, clamped
    /// to `[0, 1]`; 1 on the handle's own vertices.
    fn harmonic_weights(&mut self, factor: &Factor, set: &ElasticSet, constraints: &Constraints) {
        let n = self.y.len();
        let st = &mut self.elastic;
        if matches!(&st.harmonic, Some((id, phi)) if *id == factor.id() && phi.len() == constraints.handles.len())
        {
            return;
        }
        let mut group = vec![u32::MAX; n];
        for (k, h) in constraints.handles.iter().enumerate() {
            for &v in &h.vertices {
                group[v as usize] = k as u32;
            }
        }
        let sys = &factor.sys;
        let nu = sys.unknowns.len();
        let mut phi = vec![vec![0.0; n]; constraints.handles.len()];
        let handles: Vec<usize> = (0..constraints.handles.len()).collect();
        for chunk in handles.chunks(3) {
            st.rhs.fill(0.0);
            for (col, &k) in chunk.iter().enumerate() {
                for (r, &u) in sys.unknowns.iter().enumerate() {
                    if let Some(row) = set.q.outer_view(u as usize) {
                        let s: Real = row
                            .iter()
                            .filter(|&(j, _)| group[j] == k as u32)
                            .map(|(_, &v)| v)
                            .sum();
                        st.rhs[col * nu + r] = -s;
                    }
                }
            }
            let b = MatMut::from_column_major_slice_mut(&mut st.rhs, nu, 3);
            let mem = st.mem.as_mut().expect("sized before");
            factor.solve_in_place(b, MemStack::new(mem));
            for (col, &k) in chunk.iter().enumerate() {
                for (r, &u) in sys.unknowns.iter().enumerate() {
                    let p = st.rhs[col * nu + r];
                    if p.is_finite() {
                        phi[k][u as usize] = p.clamp(0.0, 1.0);
                    }
                }
                for &v in &constraints.handles[k].vertices {
                    phi[k][v as usize] = 1.0;
                }
            }
        }
        st.harmonic = Some((factor.id(), phi));
    }
}
