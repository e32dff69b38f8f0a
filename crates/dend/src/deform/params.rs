//! Solver parameters: energy, constraint weights, detail term and mode
//! (design.md §1, §3).

use serde::{Deserialize, Serialize};

use super::energy::Energy;
use super::DeformError;

/// How the detail term's target `δ̂` is computed (design.md §6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum DetailTerm {
    /// `δ̂ = δ` (paper eq. 15): one linear solve, no local rotations at all.
    Linear,
    /// STEP 1 / STEP 2 (paper eqs. 25–28), re-estimated every iteration.
    #[default]
    Nonlinear,
}

/// Which reading of the paper the solver follows (design.md §4.3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// Our default: the internal term's rest target rotated by the local
    /// rotations `T_i` (§4.3) and STEP 1 with the augmented columns (§6.1).
    #[default]
    Default,
    /// The paper read literally: internal term `A (X' - X)` against the
    /// unrotated rest, cross-product-only `μ`.
    Paper,
}

/// When the elastic iteration's coarse corrections stop within one
/// sequence (`solver/coarse.rs`; every [`Params::correction_period`] fine
/// iterations while they go).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, Hash)]
#[serde(rename_all = "kebab-case")]
pub enum Corrections {
    /// Once one gains less energy than the fine iterations before it did
    /// ([`Preset::Elastica`]).
    #[default]
    WhileFaster,
    /// Once one gains nothing (it is dropped or no coarse problem exists;
    /// the default, [`Preset::Characters`]): near ARAP's energy (small `k_L`) the fine iterations slow down and
    /// later corrections still pay (camel limb 32 → 27 iterations at
    /// `k_L` 0.1, `k_s` 2, coarse ratio 3).
    WhileGaining,
}

/// Which system the DEND iteration solves (design.md §4, §5, §7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default, Hash)]
#[serde(rename_all = "snake_case")]
pub enum Formulation {
    /// design.md §7: `E_T` minimised as an energy in per-vertex rotated
    /// frames, plus ARAP's stretch term; exact local and global steps, so
    /// the objective never grows (see `deform::elastic`). 4th-order normal
    /// matrix (2-ring stencil). The default.
    #[default]
    Elastic,
    /// Paper eq. (24): the internal and detail terms stacked as weighted
    /// least-squares rows, normal matrix `JᵀJ` (8th order for `E_T`, 4-ring
    /// stencil). The default before the elastic formulation.
    LeastSquares,
    /// Paper eq. (23): the square, mass-weighted Euler–Lagrange system
    /// (4th order, 2-ring stencil), solved with a symmetric approximate
    /// Jacobian (see `deform::square`).
    Square,
    /// Eq. (23) solved with a sparse LU factor of its exact, non-symmetric
    /// linear part (measured beside [`Formulation::Square`]; no CG fallback).
    SquareLu,
}

impl Formulation {
    /// Parses the CLI spelling: `elastic`, `least_squares` (or
    /// `least-squares`, `eq24`), `square` (or `eq23`), `square_lu`.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "elastic" => Formulation::Elastic,
            "least_squares" | "least-squares" | "eq24" => Formulation::LeastSquares,
            "square" | "eq23" => Formulation::Square,
            "square_lu" | "square-lu" => Formulation::SquareLu,
            _ => return None,
        })
    }
}

/// Every solver parameter, with documented defaults.
///
/// Read from JSON through [`ParamsSpec`]: a `"preset"` names the base
/// ([`Preset`], the default's when absent) and every field given overrides
/// it. Written out, every field is explicit (no preset), so a stored
/// session keeps its parameters when a default changes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "ParamsSpec")]
pub struct Params {
    /// Internal energy. Default: total curvature (`L² - 2GL`).
    pub energy: Energy,
    /// Soft-constraint weight `λ1`; `0` means hard constraints (default).
    pub lambda1: f64,
    /// Detail-term weight `λ2`. Default `1` (the paper's figures).
    pub lambda2: f64,
    /// Linear or nonlinear detail term. Default nonlinear.
    pub detail: DetailTerm,
    /// Our reading (default) or the literal paper.
    pub mode: Mode,
    /// Convergence tolerance: stop when no vertex moves more than
    /// `tol × mean edge length` in one iteration (design.md §8). Default `1e-3`.
    pub tol: f64,
    /// Iteration limit per solve. Default 100.
    pub max_iters: usize,
    /// Anderson acceleration window of the nonlinear iteration (Peng et al.
    /// 2018); `0` disables it. Default 5 (2–3× fewer iterations measured).
    pub anderson: usize,
    /// The system the iteration solves: elastic (default), eq. (24) least
    /// squares or the eq. (23) square system.
    pub formulation: Formulation,
    /// Elastic formulation only: the stretch weight `k_s` (ARAP's spokes
    /// term), dimensionless. Default [`DEFAULT_STRETCH`]
    /// ([`ELASTICA_STRETCH`] in [`Preset::Elastica`]).
    pub stretch: f64,
    /// Elastic formulation only: the bending weight `β`, dimensionless: the
    /// energy's `E_T` is weighted `k_b = β S` with `S` the surface area on
    /// the normalised mesh (mean edge length 1), so that scale and
    /// resolution do not change the pose. Default [`DEFAULT_BENDING`].
    pub bending: f64,
    /// Elastic formulation only: the area-preservation weight `k_a`
    /// (Projective Dynamics' area constraint per triangle), dimensionless.
    /// Default [`DEFAULT_AREA`].
    pub area: f64,
    /// Elastic formulation only: the weight `k_L` of the Laplacian part of
    /// the bending energy (`E2`, which is also the rotated detail term),
    /// dimensionless: `b_i = k_L λ2 k_b A_i`, so `k_L = 1` with `λ2 = 1` is
    /// `E_T` exactly. Default [`DEFAULT_LAPLACIAN`] ([`ELASTICA_LAPLACIAN`]
    /// in [`Preset::Elastica`]).
    pub laplacian: f64,
    /// Elastic formulation only: the most fine vertices per coarse vertex
    /// of the two-level iteration's coarse mesh (`deform::coarse`; meshes
    /// under 4000 vertices use fewer, never under 500 coarse vertices), at
    /// least 2. Default [`DEFAULT_COARSE_RATIO`] ([`ELASTICA_COARSE_RATIO`]
    /// in [`Preset::Elastica`]): a finer coarse mesh keeps thin parts (the
    /// camel's neck) and captures a body's swing (camel limb 40 → 21
    /// iterations with the elastica weights), at 30–50 % more time to
    /// settle on large meshes.
    pub coarse_ratio: usize,
    /// Elastic formulation only: when the coarse corrections of a sequence
    /// stop. Default [`Corrections::WhileGaining`]
    /// ([`Corrections::WhileFaster`] in [`Preset::Elastica`]).
    pub corrections: Corrections,
    /// Elastic formulation only: fine iterations between two coarse
    /// corrections of a sequence, at least 1. Default
    /// [`DEFAULT_CORRECTION_PERIOD`] ([`ELASTICA_CORRECTION_PERIOD`] in
    /// [`Preset::Elastica`]).
    pub correction_period: usize,
}

/// The default [`Params::correction_period`] (the characters' weights):
/// near ARAP's energy (`k_L` 0.1) the corrections keep gaining, and every 5
/// fine iterations instead of 10 the character edits take fewer iterations
/// (stop 29, docs/posing.md: armadillo limb 28 → 19, dino limb 26 → 18,
/// feline standard 21 → 13, camel limb 27 → 22, survey cactus 31 → 28); 7
/// was between (dino limb 32).
pub const DEFAULT_CORRECTION_PERIOD: usize = 5;

/// The [`Preset::Elastica`] correction period (the prototype: 5 let
/// corrections be rejected on the camel, 15 needed more iterations; stop
/// 25, with these weights, 5, 7 and 15 were none better than 10, and stop
/// 29: 5 takes the dino limb from 22 to 39 iterations).
pub const ELASTICA_CORRECTION_PERIOD: usize = 10;

/// The most fine iterations [`Params::correction_period`] accepts.
pub const MAX_CORRECTION_PERIOD: usize = 1000;

/// The default coarse ratio (see [`Params::coarse_ratio`]): a finer coarse
/// mesh keeps thin parts (the camel's neck) and captures a body's swing.
pub const DEFAULT_COARSE_RATIO: usize = 3;

/// The [`Preset::Elastica`] coarse ratio.
pub const ELASTICA_COARSE_RATIO: usize = 8;

/// The default Laplacian share `k_L` (see [`Params::laplacian`]): small, so
/// that the stretch term keeps the characters' edge lengths near ARAP's
/// (stop 27, docs/posing.md).
pub const DEFAULT_LAPLACIAN: f64 = 0.1;

/// The [`Preset::Elastica`] Laplacian share `k_L`: 1, `E_T` exactly.
/// Measured with the posing suite (stop 25, docs/posing.md), a smaller
/// `k_L` lowers the characters' distortion a little but the 300° bar keeps
/// less of its area (0.80 at 1, 0.789 at 0.6) and the 120° cylinder bends
/// less evenly (CV 0.49 at 1, 0.60 at 0.6).
pub const ELASTICA_LAPLACIAN: f64 = 1.0;

/// The default stretch weight `k_s` (see [`Params::stretch`]).
pub const DEFAULT_STRETCH: f64 = 3.0;

/// The [`Preset::Elastica`] stretch weight `k_s`.
pub const ELASTICA_STRETCH: f64 = 1.0;

/// The area weight `k_a` of both presets (see [`Params::area`]).
pub const DEFAULT_AREA: f64 = 15.0;

/// The bending weight `β` of both presets (see [`Params::bending`]).
pub const DEFAULT_BENDING: f64 = 3e-3;

/// A named set of parameters: what the API's `"preset"` and the CLI's
/// `--preset` name (issue #33). Explicit fields override a preset's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Preset {
    /// The default: ARAP-like edge lengths on characters (`k_s` 3, `k_L`
    /// 0.1, coarse ratio 3, corrections while gaining every 5 fine
    /// iterations). On the posing suite (stop 29, docs/posing.md) 11 of
    /// the 12 character edits meet every rule against 7 with
    /// [`Preset::Elastica`]; twisted square tubes keep their sections (135°:
    /// min area 0.925, 2.8° from an even twist; converged ARAP 0.90 / 3.6°).
    #[default]
    Characters,
    /// The paper's even bend and twist (`k_s` 1, `k_L` 1: `E_T` exactly,
    /// coarse ratio 8, corrections while faster every 10): the 300° bar
    /// keeps min area 0.80 (characters 0.60), the survey bar's twist is
    /// 0.6° from its ramp (9.2°), and the pose is the same on a mesh and
    /// its subdivision (0.2–0.4 % of the diagonal, characters 1.8–3.4 %,
    /// libigl's ARAP 2.3–6.4 %; stop 31).
    Elastica,
}

impl Preset {
    /// Every preset, the default first.
    pub const ALL: [Preset; 2] = [Preset::Characters, Preset::Elastica];

    /// The preset's name on the wire and the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Characters => "characters",
            Preset::Elastica => "elastica",
        }
    }

    /// A short title for a menu.
    pub fn label(self) -> &'static str {
        match self {
            Preset::Characters => "Characters",
            Preset::Elastica => "Elastica (even bend and twist)",
        }
    }

    /// One sentence on what the preset is for.
    pub fn description(self) -> &'static str {
        match self {
            Preset::Characters => {
                "Posing characters and creatures: edge lengths kept close to rest, limbs swing freely (the default)."
            }
            Preset::Elastica => {
                "The paper's elastica: bends and twists spread evenly along bars and tubes, cross-sections kept; the same pose at any mesh resolution."
            }
        }
    }

    /// The preset's parameters.
    pub fn params(self) -> Params {
        match self {
            Preset::Characters => Params::default(),
            Preset::Elastica => Params::elastica(),
        }
    }

    /// Parses a name (`characters`, `elastica`).
    pub fn from_name(name: &str) -> Option<Self> {
        Preset::ALL.into_iter().find(|p| p.name() == name)
    }
}

/// Session parameters as a client writes them: an optional [`Preset`] and
/// any fields that override it (unknown fields are refused).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ParamsSpec {
    /// The base parameters (default [`Preset::Characters`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[serde(deserialize_with = "present")]
    pub preset: Option<Preset>,
    /// Overrides [`Params::energy`].
    #[serde(deserialize_with = "present")]
    pub energy: Option<Energy>,
    /// Overrides [`Params::lambda1`].
    #[serde(deserialize_with = "present")]
    pub lambda1: Option<f64>,
    /// Overrides [`Params::lambda2`].
    #[serde(deserialize_with = "present")]
    pub lambda2: Option<f64>,
    /// Overrides [`Params::detail`].
    #[serde(deserialize_with = "present")]
    pub detail: Option<DetailTerm>,
    /// Overrides [`Params::mode`].
    #[serde(deserialize_with = "present")]
    pub mode: Option<Mode>,
    /// Overrides [`Params::tol`].
    #[serde(deserialize_with = "present")]
    pub tol: Option<f64>,
    /// Overrides [`Params::max_iters`].
    #[serde(deserialize_with = "present")]
    pub max_iters: Option<usize>,
    /// Overrides [`Params::anderson`].
    #[serde(deserialize_with = "present")]
    pub anderson: Option<usize>,
    /// Overrides [`Params::formulation`].
    #[serde(deserialize_with = "present")]
    pub formulation: Option<Formulation>,
    /// Overrides [`Params::stretch`].
    #[serde(deserialize_with = "present")]
    pub stretch: Option<f64>,
    /// Overrides [`Params::bending`].
    #[serde(deserialize_with = "present")]
    pub bending: Option<f64>,
    /// Overrides [`Params::area`].
    #[serde(deserialize_with = "present")]
    pub area: Option<f64>,
    /// Overrides [`Params::laplacian`].
    #[serde(deserialize_with = "present")]
    pub laplacian: Option<f64>,
    /// Overrides [`Params::coarse_ratio`].
    #[serde(deserialize_with = "present")]
    pub coarse_ratio: Option<usize>,
    /// Overrides [`Params::corrections`].
    #[serde(deserialize_with = "present")]
    pub corrections: Option<Corrections>,
    /// Overrides [`Params::correction_period`].
    #[serde(deserialize_with = "present")]
    pub correction_period: Option<usize>,
}

/// Reads a field that is present: `null` is refused rather than read as
/// "unset", because a client's NaN is written `null` by `JSON.stringify`.
fn present<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    T::deserialize(d).map(Some)
}

impl From<ParamsSpec> for Params {
    fn from(s: ParamsSpec) -> Params {
        let b = s.preset.unwrap_or_default().params();
        Params {
            energy: s.energy.unwrap_or(b.energy),
            lambda1: s.lambda1.unwrap_or(b.lambda1),
            lambda2: s.lambda2.unwrap_or(b.lambda2),
            detail: s.detail.unwrap_or(b.detail),
            mode: s.mode.unwrap_or(b.mode),
            tol: s.tol.unwrap_or(b.tol),
            max_iters: s.max_iters.unwrap_or(b.max_iters),
            anderson: s.anderson.unwrap_or(b.anderson),
            formulation: s.formulation.unwrap_or(b.formulation),
            stretch: s.stretch.unwrap_or(b.stretch),
            bending: s.bending.unwrap_or(b.bending),
            area: s.area.unwrap_or(b.area),
            laplacian: s.laplacian.unwrap_or(b.laplacian),
            coarse_ratio: s.coarse_ratio.unwrap_or(b.coarse_ratio),
            corrections: s.corrections.unwrap_or(b.corrections),
            correction_period: s.correction_period.unwrap_or(b.correction_period),
        }
    }
}

impl Default for Params {
    fn default() -> Self {
        Params {
            energy: Energy::default(),
            lambda1: 0.0,
            lambda2: 1.0,
            detail: DetailTerm::Nonlinear,
            mode: Mode::Default,
            tol: 1e-3,
            max_iters: 100,
            anderson: 5,
            formulation: Formulation::Elastic,
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

impl Params {
    /// The [`Preset::Elastica`] parameters: the paper's even bend and
    /// twist (`k_s` [`ELASTICA_STRETCH`], `k_L` [`ELASTICA_LAPLACIAN`],
    /// coarse ratio [`ELASTICA_COARSE_RATIO`], corrections
    /// [`Corrections::WhileFaster`] every [`ELASTICA_CORRECTION_PERIOD`]).
    pub fn elastica() -> Params {
        Params {
            stretch: ELASTICA_STRETCH,
            laplacian: ELASTICA_LAPLACIAN,
            coarse_ratio: ELASTICA_COARSE_RATIO,
            corrections: Corrections::WhileFaster,
            correction_period: ELASTICA_CORRECTION_PERIOD,
            ..Params::default()
        }
    }

    /// The literal paper: [`Mode::Paper`] with the table's `L² - 2LG`,
    /// solved as eq. (24)'s least squares.
    pub fn paper() -> Self {
        Params {
            energy: Energy::TotalCurvaturePaper,
            mode: Mode::Paper,
            formulation: Formulation::LeastSquares,
            ..Params::default()
        }
    }

    /// Rejects NaN, negative or out-of-range values.
    pub fn validate(&self) -> Result<(), DeformError> {
        let bad = |name: &'static str, value: f64| DeformError::InvalidParam { name, value };
        if !(self.lambda1.is_finite() && self.lambda1 >= 0.0) {
            return Err(bad("lambda1", self.lambda1));
        }
        if !(self.lambda2.is_finite() && self.lambda2 >= 0.0) {
            return Err(bad("lambda2", self.lambda2));
        }
        if !(self.tol.is_finite() && self.tol > 0.0) {
            return Err(bad("tol", self.tol));
        }
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
        if self.formulation == Formulation::Elastic {
            // the elastic formulation's bending energy is total curvature
            // (or thin plate), in our reading: the others belong to the
            // paper's formulations (least_squares, square)
            if !self.energy.has_elastic_form() {
                return Err(DeformError::Unsupported {
                    what: "this energy with the elastic formulation (use total or thin-plate, or formulation least_squares)",
                });
            }
            if self.mode == Mode::Paper {
                return Err(DeformError::Unsupported {
                    what: "the paper mode with the elastic formulation (use formulation least_squares)",
                });
            }
            // with no stretch, no area and no Laplacian rows nothing holds
            // the free vertices' tangential positions: a singular system
            let laplacian_rows = self.lambda2 * self.laplacian > 0.0 && self.bending > 0.0;
            if self.stretch == 0.0 && self.area == 0.0 && !laplacian_rows {
                return Err(bad("stretch", self.stretch));
            }
        }
        if self.anderson > super::anderson::MAX_WINDOW {
            return Err(bad("anderson", self.anderson as f64));
        }
        if let Energy::Combined { ks, kb } = self.energy {
            if !(ks.is_finite() && ks >= 0.0) {
                return Err(bad("ks", ks));
            }
            if !(kb.is_finite() && kb >= 0.0) || ks + kb == 0.0 {
                return Err(bad("kb", kb));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(json: &str) -> Result<Params, serde_json::Error> {
        serde_json::from_str(json)
    }

    #[test]
    fn an_empty_object_is_the_default_preset() {
        assert_eq!(read("{}").unwrap(), Params::default());
        assert_eq!(Preset::default().params(), Params::default());
        assert_eq!(
            read(r#"{"preset": "characters"}"#).unwrap(),
            Params::default()
        );
    }

    #[test]
    fn a_preset_is_its_parameters_and_explicit_fields_override_it() {
        let e = read(r#"{"preset": "elastica"}"#).unwrap();
        assert_eq!(e, Params::elastica());
        assert_ne!(e, Params::default());
        let o = read(r#"{"preset": "elastica", "stretch": 2.5, "max_iters": 7}"#).unwrap();
        assert_eq!(
            o,
            Params {
                stretch: 2.5,
                max_iters: 7,
                ..Params::elastica()
            }
        );
        // an explicit field equal to the other preset's does not switch it
        let c = read(r#"{"preset": "characters", "laplacian": 1.0}"#).unwrap();
        assert_eq!(c.stretch, Params::default().stretch);
        assert_eq!(c.laplacian, 1.0);
    }

    #[test]
    fn written_parameters_read_back_unchanged_whatever_the_default() {
        // a stored session writes every field: it must read back as itself,
        // not as the current default (so changing a default keeps it)
        for p in [Params::default(), Params::elastica(), Params::paper()] {
            let v = serde_json::to_value(p).unwrap();
            assert!(v.get("preset").is_none());
            assert_eq!(serde_json::from_value::<Params>(v).unwrap(), p);
        }
    }

    #[test]
    fn unknown_fields_and_presets_are_refused() {
        assert!(read(r#"{"stiffness": 1}"#).is_err());
        assert!(read(r#"{"preset": "general"}"#).is_err());
        assert!(read(r#"{"preset": 3}"#).is_err());
    }

    #[test]
    fn null_is_refused_not_read_as_unset() {
        for field in ["preset", "tol", "lambda1", "stretch", "max_iters", "energy"] {
            let r = read(&format!(r#"{{"{field}": null}}"#));
            assert!(r.is_err(), "{field}: null was accepted as {r:?}");
        }
        assert!(read(r#"{"tol": 1e-4}"#).is_ok());
    }

    #[test]
    fn preset_names_round_trip() {
        for p in Preset::ALL {
            assert_eq!(Preset::from_name(p.name()), Some(p));
            let wire = serde_json::to_value(p).unwrap();
            assert_eq!(wire, serde_json::Value::from(p.name()));
            assert!(p.params().validate().is_ok());
        }
        assert_eq!(Preset::from_name("general"), None);
    }
}
