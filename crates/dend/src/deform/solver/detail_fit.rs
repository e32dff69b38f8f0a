//! The coarse levels' detail weight, fitted to the fine energy by what the
//! corrections gain.
//!
//! A correction (`solver/multilevel.rs`) predicts its own gain: the fall of
//! the coarse objective, `E_c − 2⟨s, Y_c⟩`, over its solve, in the fine
//! level's units (times `(h_f / h_c)²`: the levels' normalised energies
//! scale with the inverse square of their unit). The fine energy then
//! gains `ρ` times that. For a coarse model whose curvature along the
//! correction is `k` times the fine one's, a quadratic model gives
//! `ρ = 2 − 1/k`: `ρ ≈ 1` where the model fits, `ρ > 1` where it is too
//! stiff (the correction stops short), `ρ < 1` where it is too soft or
//! does not hold.
//!
//! Measured over the first corrections of `drag_sim --path arc`
//! (docs/performance.md): camel_9770 0.56–1.04, the survey's bumpy plane
//! 0.11–0.49 (later 0.8–1.0), feline_50k 1.11–1.46, armadillo_43k
//! 1.14–1.69. The characters' coarse models are too stiff in their detail
//! term `E2`: their levels lose the thin parts' curvature, and their
//! rest Laplacian coordinates `δ` stand for a rougher surface (the
//! armadillo's first level's own minimum stands 8.9 % of the diagonal from
//! the fine one, 0.6 % with its `k_L` at a quarter). So a fine mesh
//! measures `ρ` on the first [`FIT_SAMPLES`] corrections of a constraint
//! set, and where their median exceeds [`RHO_STIFF`] its coarse levels
//! take the detail weight times [`SOFT_DETAIL`], each level again below
//! the one above it (their corrections then measure `ρ` 0.75–1.0 on the
//! armadillo), from the next sequence of the set on: a session's next
//! drags and settles. The fine problem, its minimum and the convergence
//! test do not change: only the corrections' model.
//!
//! `drag_sim --path arc --gestures 3` (the gesture three times on one
//! deformer), the third settle against the first, in fine-iteration
//! equivalents of work: armadillo_43k 112.6 → 94.5 (2.18 → 1.88 s),
//! feline_50k 41.8 → 39.4; camel_9770, igea_134k and the survey's bumpy
//! plane keep their levels, and the posing suite (one solve per edit) its
//! iterations and verdicts.

use crate::deform::params::Params;
use crate::mesh::Real;

/// Corrections whose `ρ` decide a constraint set's coarse detail weight.
pub const FIT_SAMPLES: usize = 3;

/// The median `ρ` above which the coarse levels are too stiff: past the
/// fitting model's 1 by more than the spread of a fitting level's samples
/// (the camel's first three: 0.67, 0.56, 1.04).
pub const RHO_STIFF: Real = 1.05;

/// The detail weight `k_L` of each coarse level against the level above
/// it once the levels are too stiff. A quarter, compounded down the
/// hierarchy, gave the work of `drag_sim --path arc` (one-shot / settle,
/// fine-iteration equivalents) armadillo_43k 101.6 / 112.6 → 73.0 / 96.7
/// and feline_50k 37.9 / 41.8 → 34.2 / 39.4; a quarter on every level
/// without compounding, 103.1 / 97.4 and 34.7 / 36.5 (docs/performance.md).
pub const SOFT_DETAIL: Real = 0.25;

/// A predicted gain below this share of the objective is rounding, not a
/// sample.
const MIN_PREDICTED: Real = 1e-10;

/// Where a deformer's coarse detail weight stands.
#[derive(Debug, Clone, PartialEq)]
enum Fit {
    /// A coarse level's deformer: the scale its parent chose, for the
    /// levels below it.
    Inherited,
    /// Measuring, for the fine factor of this id (`None`: no correction
    /// yet since the last constraint set).
    Measuring {
        factor: Option<u64>,
        samples: Vec<Real>,
    },
    /// Chosen for the fine factor of this id.
    Decided { factor: u64 },
}

/// A deformer's coarse detail weight (module docs).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct DetailFit {
    /// `k_L` of the levels below against this deformer's own.
    scale: Real,
    fit: Fit,
}

impl Default for DetailFit {
    /// A fine mesh's: measuring, the levels at the fine weight.
    fn default() -> Self {
        DetailFit {
            scale: 1.0,
            fit: Fit::Measuring {
                factor: None,
                samples: Vec::new(),
            },
        }
    }
}

impl DetailFit {
    /// A coarse level's deformer, whose levels below take `scale` again.
    pub(super) fn inherited(scale: Real) -> Self {
        DetailFit {
            scale,
            fit: Fit::Inherited,
        }
    }

    /// The detail weight of the levels below, against this deformer's.
    pub(super) fn scale(&self) -> Real {
        self.scale
    }

    /// `params` with the detail weight `k_L` times [`DetailFit::scale`]:
    /// the levels below's.
    pub(super) fn below(&self, params: &Params) -> Params {
        let s = self.scale;
        params.with_elastic(|e| e.laplacian *= s)
    }

    /// Measures again from the next correction on (a new constraint set is
    /// being built); a coarse level's inherited scale stays. Returns
    /// whether the scale changed.
    pub(super) fn restart(&mut self) -> bool {
        if self.fit == Fit::Inherited {
            return false;
        }
        let changed = self.scale != 1.0;
        *self = DetailFit::default();
        changed
    }

    /// Before a correction with the fine factor `factor`: another factor
    /// than the one measured or decided for (another constraint set)
    /// measures again. Returns whether the scale changed.
    pub(super) fn with_factor(&mut self, factor: u64) -> bool {
        match &mut self.fit {
            Fit::Inherited => false,
            Fit::Measuring { factor: f, .. } if f.is_none_or(|f| f == factor) => {
                *f = Some(factor);
                false
            }
            Fit::Decided { factor: f } if *f == factor => false,
            _ => {
                let changed = self.restart();
                self.fit = Fit::Measuring {
                    factor: Some(factor),
                    samples: Vec::new(),
                };
                changed
            }
        }
    }

    /// A kept correction with the fine factor `factor` gained `gain` of
    /// the fine objective `e` where its coarse solve predicted `predicted`
    /// (module docs): a sample, until there are [`FIT_SAMPLES`].
    pub(super) fn record(&mut self, factor: u64, e: Real, gain: Real, predicted: Real) {
        let Fit::Measuring {
            factor: Some(f),
            samples,
        } = &mut self.fit
        else {
            return;
        };
        // (NaN predictions are not samples either)
        let measurable = predicted > MIN_PREDICTED * e.abs();
        if *f == factor && measurable && gain.is_finite() && samples.len() < FIT_SAMPLES {
            samples.push(gain / predicted);
        }
    }

    /// At the start of a sequence: once [`FIT_SAMPLES`] are in, decides
    /// the scale for the factor they were measured with. Returns whether
    /// it changed: the coarse problems built before are stale. (Not within
    /// a sequence: the levels rebuilt there cost more than the rest of it
    /// gains, feline_50k's first settle 892 → 1,064 ms.)
    pub(super) fn decide(&mut self) -> bool {
        let Fit::Measuring {
            factor: Some(factor),
            samples,
        } = &mut self.fit
        else {
            return false;
        };
        if samples.len() < FIT_SAMPLES {
            return false;
        }
        let rho = median(samples);
        self.fit = Fit::Decided { factor: *factor };
        let soften = rho > RHO_STIFF;
        if soften {
            self.scale = SOFT_DETAIL;
        }
        tracing::debug!(rho, scale = self.scale, "coarse detail weight");
        soften
    }
}

/// The median of `x` (the mean of the middle two for an even count).
fn median(x: &mut [Real]) -> Real {
    x.sort_by(Real::total_cmp);
    let n = x.len();
    if n % 2 == 1 {
        x[n / 2]
    } else {
        0.5 * (x[n / 2 - 1] + x[n / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decide(samples: &[Real]) -> (DetailFit, bool) {
        let mut d = DetailFit::default();
        d.with_factor(7);
        for &rho in samples {
            assert!(!d.decide(), "decided before {FIT_SAMPLES} samples");
            d.record(7, 100.0, rho, 1.0);
        }
        let changed = d.decide();
        (d, changed)
    }

    #[test]
    fn a_stiff_median_softens_the_levels_once() {
        // the armadillo's first three corrections
        let (d, changed) = decide(&[1.14, 1.31, 1.31]);
        assert!(changed);
        assert_eq!(d.scale(), SOFT_DETAIL);
        // later samples and sequences change nothing
        let mut d2 = d.clone();
        d2.record(7, 100.0, 0.1, 1.0);
        assert!(!d2.decide());
        assert_eq!(d2, d);
    }

    #[test]
    fn a_fitting_or_soft_median_keeps_them() {
        // the camel's, the bumpy plane's, and one stiff outlier
        for s in [[0.67, 0.56, 1.04], [0.13, 0.11, 0.49], [0.9, 3.0, 1.0]] {
            let (d, changed) = decide(&s);
            assert!(!changed, "{s:?}");
            assert_eq!(d.scale(), 1.0, "{s:?}");
        }
    }

    #[test]
    fn rounding_and_other_factors_are_not_samples() {
        let mut d = DetailFit::default();
        d.with_factor(7);
        for _ in 0..5 {
            // a prediction at rounding's size, and another set's correction
            d.record(7, 1e6, 2.0, 1e-6);
            d.record(8, 1.0, 2.0, 1.0);
            assert!(!d.decide());
        }
        d.record(7, 1.0, 2.0, 1.0);
        d.record(7, 1.0, 2.0, 1.0);
        assert!(!d.decide());
        d.record(7, 1.0, 2.0, 1.0);
        assert!(d.decide(), "the third sample decides");
    }

    #[test]
    fn a_new_constraint_set_measures_again() {
        let (mut d, _) = decide(&[2.0, 2.0, 2.0]);
        assert!(!d.with_factor(7), "the same set keeps its scale");
        assert!(d.with_factor(9), "another set starts at the fine weight");
        assert_eq!(d.scale(), 1.0);
        for _ in 0..3 {
            assert!(!d.decide());
            d.record(9, 1.0, 2.0, 1.0);
        }
        assert!(d.decide());
        assert!(d.restart());
        assert_eq!(d, DetailFit::default());
    }

    #[test]
    fn an_inherited_scale_is_fixed() {
        let mut d = DetailFit::inherited(SOFT_DETAIL);
        assert!(!d.with_factor(3));
        assert!(!d.restart());
        for _ in 0..5 {
            d.record(3, 1.0, 2.0, 1.0);
            assert!(!d.decide());
        }
        assert_eq!(d.scale(), SOFT_DETAIL);
        let p = d.below(&Params::default());
        let (k, k0) = (
            p.elastic().map(|e| e.laplacian),
            Params::default().elastic().map(|e| e.laplacian),
        );
        assert_eq!(k, k0.map(|k| k * SOFT_DETAIL));
    }
}
