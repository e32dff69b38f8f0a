//! The elastic formulation's own parameters (design.md §7): its weights
//! and the schedule of its coarse-level corrections.

use serde::{Deserialize, Serialize};

use crate::deform::error::DeformError;

/// When the elastic iteration's coarse corrections stop within one
/// sequence (`solver/multilevel.rs`; every [`ElasticParams::correction_period`] fine
/// iterations while they go).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Corrections {
    /// Once one gains less energy than the fine iterations before it did
    /// ([`Preset::Elastica`](super::Preset::Elastica)).
    #[default]
    WhileFaster,
    /// Once one gains nothing (it is dropped or no coarse problem exists;
    /// the default, [`Preset::Characters`](super::Preset::Characters)): near ARAP's energy (small `k_L`) the fine iterations slow down and
    /// later corrections still pay (camel limb 32 → 27 iterations at
    /// `k_L` 0.1, `k_s` 2, coarse ratio 3).
    WhileGaining,
}

/// The parameters only the elastic formulation reads ([`super::Formulation::Elastic`]):
/// its energy's weights and its two-level iteration's schedule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ElasticParams {
    /// The stretch weight `k_s` (ARAP's spokes term), dimensionless.
    /// Default [`DEFAULT_STRETCH`] ([`ELASTICA_STRETCH`] in
    /// [`Preset::Elastica`](super::Preset::Elastica)).
    pub stretch: f64,
    /// The bending weight `β`, dimensionless: the energy's `E_T` is
    /// weighted `k_b = β S` with `S` the surface area on the normalised
    /// mesh (mean edge length 1), so that scale and resolution do not
    /// change the pose. Default [`DEFAULT_BENDING`].
    pub bending: f64,
    /// The area-preservation weight `k_a` (Projective Dynamics' area
    /// constraint per triangle), dimensionless. Default [`DEFAULT_AREA`].
    pub area: f64,
    /// The weight `k_L` of the Laplacian part of the bending energy (`E2`,
    /// which is also the rotated detail term), dimensionless:
    /// `b_i = k_L λ2 k_b A_i`, so `k_L = 1` with `λ2 = 1` is `E_T` exactly.
    /// Default [`DEFAULT_LAPLACIAN`] ([`ELASTICA_LAPLACIAN`] in
    /// [`Preset::Elastica`](super::Preset::Elastica)).
    pub laplacian: f64,
    /// The most fine vertices per coarse vertex of the two-level
    /// iteration's coarse mesh (`deform::coarse`; meshes under 4000
    /// vertices use fewer, never under 500 coarse vertices), at least 2.
    /// Default [`DEFAULT_COARSE_RATIO`] ([`ELASTICA_COARSE_RATIO`] in
    /// [`Preset::Elastica`](super::Preset::Elastica)): a finer coarse mesh keeps thin parts (the
    /// camel's neck) and captures a body's swing (camel limb 40 → 21
    /// iterations with the elastica weights), at 30–50 % more time to
    /// settle on large meshes.
    pub coarse_ratio: usize,
    /// When the coarse corrections of a sequence stop. Default
    /// [`Corrections::WhileGaining`] ([`Corrections::WhileFaster`] in
    /// [`Preset::Elastica`](super::Preset::Elastica)).
    pub corrections: Corrections,
    /// Fine iterations between two coarse corrections of a sequence, at
    /// least 1. Default [`DEFAULT_CORRECTION_PERIOD`]
    /// ([`ELASTICA_CORRECTION_PERIOD`] in [`Preset::Elastica`](super::Preset::Elastica)).
    pub correction_period: usize,
}

impl Default for ElasticParams {
    /// The [`Preset::Characters`](super::Preset::Characters) weights.
    fn default() -> Self {
        ElasticParams {
            stretch: DEFAULT_STRETCH,
            bending: DEFAULT_BENDING,
            area: DEFAULT_AREA,
            laplacian: DEFAULT_LAPLACIAN,
            coarse_ratio: DEFAULT_COARSE_RATIO,
            corrections: Corrections::WhileGaining,
            correction_period: DEFAULT_CORRECTION_PERIOD,
        }
    }
}

impl ElasticParams {
    /// The [`Preset::Elastica`](super::Preset::Elastica) weights: the paper's even bend and twist
    /// (`k_s` [`ELASTICA_STRETCH`], `k_L` [`ELASTICA_LAPLACIAN`], coarse
    /// ratio [`ELASTICA_COARSE_RATIO`], corrections
    /// [`Corrections::WhileFaster`] every [`ELASTICA_CORRECTION_PERIOD`]).
    pub fn elastica() -> Self {
        ElasticParams {
            stretch: ELASTICA_STRETCH,
            laplacian: ELASTICA_LAPLACIAN,
            coarse_ratio: ELASTICA_COARSE_RATIO,
            corrections: Corrections::WhileFaster,
            correction_period: ELASTICA_CORRECTION_PERIOD,
            ..ElasticParams::default()
        }
    }

    /// Rejects NaN, negative or out-of-range values, each on its own
    /// (what depends on the other parameters is in
    /// [`super::Params::validate`]).
    pub fn validate(&self) -> Result<(), DeformError> {
        let bad = |name: &'static str, value: f64| DeformError::InvalidParam { name, value };
        if self.coarse_ratio < 2 {
            return Err(bad("coarse_ratio", self.coarse_ratio as f64));
        }
        if !(1..=MAX_CORRECTION_PERIOD).contains(&self.correction_period) {
            return Err(bad("correction_period", self.correction_period as f64));
        }
        if !(self.stretch.is_finite() && self.stretch >= 0.0) {
            return Err(bad("stretch", self.stretch));
        }
        if !(self.bending.is_finite() && self.bending >= 0.0) || self.stretch + self.bending == 0.0
        {
            return Err(bad("bending", self.bending));
        }
        if !(self.area.is_finite() && self.area >= 0.0) {
            return Err(bad("area", self.area));
        }
        if !(self.laplacian.is_finite() && self.laplacian >= 0.0) {
            return Err(bad("laplacian", self.laplacian));
        }
        Ok(())
    }
}

/// The default [`ElasticParams::correction_period`] (the characters' weights):
/// near ARAP's energy (`k_L` 0.1) the corrections keep gaining, and every 5
/// fine iterations instead of 10 the character edits take fewer iterations
/// (stop 29, docs/posing.md: armadillo limb 28 → 19, dino limb 26 → 18,
/// feline standard 21 → 13, camel limb 27 → 22, survey cactus 31 → 28); 7
/// was between (dino limb 32).
pub const DEFAULT_CORRECTION_PERIOD: usize = 5;

/// The [`Preset::Elastica`](super::Preset::Elastica) correction period (the prototype: 5 let
/// corrections be rejected on the camel, 15 needed more iterations; stop
/// 25, with these weights, 5, 7 and 15 were none better than 10, and stop
/// 29: 5 takes the dino limb from 22 to 39 iterations).
pub const ELASTICA_CORRECTION_PERIOD: usize = 10;

/// The most fine iterations [`ElasticParams::correction_period`] accepts.
pub const MAX_CORRECTION_PERIOD: usize = 1000;

/// The default coarse ratio (see [`ElasticParams::coarse_ratio`]): a finer coarse
/// mesh keeps thin parts (the camel's neck) and captures a body's swing.
/// With the hierarchy ([`Levels::Many`](crate::deform::Levels::Many)),
/// each level has about a quarter of the vertices of the one above:
/// ratio 3 made levels whose cycles cost more than they gained
/// (armadillo one-shot 152 fine iterations of work against 104), ratio 5
/// left the survey bar's coarse levels too coarse for its twist (capped
/// at 100 iterations, against 43) (docs/performance.md).
pub const DEFAULT_COARSE_RATIO: usize = 4;

/// The [`Preset::Elastica`](super::Preset::Elastica) coarse ratio.
pub const ELASTICA_COARSE_RATIO: usize = 8;

/// The default Laplacian share `k_L` (see [`ElasticParams::laplacian`]): small, so
/// that the stretch term keeps the characters' edge lengths near ARAP's
/// (stop 27, docs/posing.md).
pub const DEFAULT_LAPLACIAN: f64 = 0.1;

/// The [`Preset::Elastica`](super::Preset::Elastica) Laplacian share `k_L`: 1, `E_T` exactly.
/// Measured with the posing suite (stop 25, docs/posing.md), a smaller
/// `k_L` lowers the characters' distortion a little but the 300° bar keeps
/// less of its area (0.80 at 1, 0.789 at 0.6) and the 120° cylinder bends
/// less evenly (CV 0.49 at 1, 0.60 at 0.6).
pub const ELASTICA_LAPLACIAN: f64 = 1.0;

/// The default stretch weight `k_s` (see [`ElasticParams::stretch`]).
pub const DEFAULT_STRETCH: f64 = 3.0;

/// The [`Preset::Elastica`](super::Preset::Elastica) stretch weight `k_s`.
pub const ELASTICA_STRETCH: f64 = 1.0;

/// The area weight `k_a` of both presets (see [`ElasticParams::area`]).
pub const DEFAULT_AREA: f64 = 15.0;

/// The bending weight `β` of both presets (see [`ElasticParams::bending`]).
pub const DEFAULT_BENDING: f64 = 3e-3;
