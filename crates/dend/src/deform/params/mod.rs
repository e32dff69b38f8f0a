//! Solver parameters: energy, constraint weights, detail term, and the
//! formulation with the parameters only it reads (design.md §1, §3).

use serde::{Deserialize, Serialize};

use super::energy::Energy;
use super::DeformError;

mod elastic;
mod spec;

pub use elastic::{
    Corrections, ElasticParams, DEFAULT_AREA, DEFAULT_BENDING, DEFAULT_COARSE_RATIO,
    DEFAULT_CORRECTION_PERIOD, DEFAULT_LAPLACIAN, DEFAULT_STRETCH, ELASTICA_COARSE_RATIO,
    ELASTICA_CORRECTION_PERIOD, ELASTICA_LAPLACIAN, ELASTICA_STRETCH,
};
pub use spec::{ParamsSpec, Preset};

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

/// The parameters of the paper's formulations (eq. (24) least squares and
/// the eq. (23) square system).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct PaperParams {
    /// Our reading (default) or the literal paper.
    pub mode: Mode,
}

/// The system the DEND iteration solves ([`Formulation`]) with the
/// parameters that only it reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FormulationParams {
    /// [`Formulation::Elastic`] (the default).
    Elastic(ElasticParams),
    /// [`Formulation::LeastSquares`].
    LeastSquares(PaperParams),
    /// [`Formulation::Square`].
    Square(PaperParams),
    /// [`Formulation::SquareLu`].
    SquareLu(PaperParams),
}

impl Default for FormulationParams {
    fn default() -> Self {
        FormulationParams::Elastic(ElasticParams::default())
    }
}

impl FormulationParams {
    /// The paper formulation `kind` with `paper`'s parameters, or the
    /// default elastic one for [`Formulation::Elastic`].
    pub fn paper(kind: Formulation, paper: PaperParams) -> Self {
        match kind {
            Formulation::Elastic => FormulationParams::default(),
            Formulation::LeastSquares => FormulationParams::LeastSquares(paper),
            Formulation::Square => FormulationParams::Square(paper),
            Formulation::SquareLu => FormulationParams::SquareLu(paper),
        }
    }

    /// Which formulation this is (its name on the wire).
    pub fn kind(&self) -> Formulation {
        match self {
            FormulationParams::Elastic(_) => Formulation::Elastic,
            FormulationParams::LeastSquares(_) => Formulation::LeastSquares,
            FormulationParams::Square(_) => Formulation::Square,
            FormulationParams::SquareLu(_) => Formulation::SquareLu,
        }
    }

    /// The elastic formulation's parameters, `None` for the paper's.
    pub fn elastic(&self) -> Option<&ElasticParams> {
        match self {
            FormulationParams::Elastic(e) => Some(e),
            _ => None,
        }
    }

    /// The paper formulations' parameters, `None` for the elastic one.
    pub fn paper_params(&self) -> Option<&PaperParams> {
        match self {
            FormulationParams::Elastic(_) => None,
            FormulationParams::LeastSquares(p)
            | FormulationParams::Square(p)
            | FormulationParams::SquareLu(p) => Some(p),
        }
    }
}

/// Every solver parameter, with documented defaults: those every
/// formulation reads, and the formulation with its own.
///
/// Read from JSON through [`ParamsSpec`]: a `"preset"` names the base
/// ([`Preset`], the default's when absent) and every field given overrides
/// it. Written out, every field is explicit (no preset), so a stored
/// session keeps its parameters when a default changes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ParamsSpec", into = "spec::WrittenParams")]
pub struct Params {
    /// Internal energy. Default: total curvature (`L² - 2GL`).
    pub energy: Energy,
    /// Soft-constraint weight `λ1`; `0` means hard constraints (default).
    pub lambda1: f64,
    /// Detail-term weight `λ2`. Default `1` (the paper's figures).
    pub lambda2: f64,
    /// Linear or nonlinear detail term. Default nonlinear.
    pub detail: DetailTerm,
    /// Convergence tolerance: stop when no vertex moves more than
    /// `tol × mean edge length` in one iteration (design.md §8). Default `1e-3`.
    pub tol: f64,
    /// Iteration limit per solve. Default 100.
    pub max_iters: usize,
    /// Anderson acceleration window of the nonlinear iteration (Peng et al.
    /// 2018); `0` disables it. Default 5 (2–3× fewer iterations measured).
    pub anderson: usize,
    /// The system the iteration solves, with its own parameters: elastic
    /// (default), eq. (24) least squares or the eq. (23) square system.
    pub formulation: FormulationParams,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            energy: Energy::default(),
            lambda1: 0.0,
            lambda2: 1.0,
            detail: DetailTerm::Nonlinear,
            tol: 1e-3,
            max_iters: 100,
            anderson: 5,
            formulation: FormulationParams::default(),
        }
    }
}

impl Params {
    /// The [`Preset::Elastica`] parameters: the default ones with
    /// [`ElasticParams::elastica`].
    pub fn elastica() -> Params {
        Params {
            formulation: FormulationParams::Elastic(ElasticParams::elastica()),
            ..Params::default()
        }
    }

    /// The literal paper: [`Mode::Paper`] with the table's `L² - 2LG`,
    /// solved as eq. (24)'s least squares.
    pub fn paper() -> Self {
        Params {
            energy: Energy::TotalCurvaturePaper,
            formulation: FormulationParams::LeastSquares(PaperParams { mode: Mode::Paper }),
            ..Params::default()
        }
    }

    /// These parameters with the formulation `kind`, its own parameters at
    /// their defaults (the paper's in our reading, [`Mode::Default`]).
    pub fn with_formulation(self, kind: Formulation) -> Self {
        let formulation = match kind {
            Formulation::Elastic => FormulationParams::default(),
            other => FormulationParams::paper(other, PaperParams::default()),
        };
        Params {
            formulation,
            ..self
        }
    }

    /// The elastic formulation's parameters, `None` for the paper's.
    pub fn elastic(&self) -> Option<&ElasticParams> {
        self.formulation.elastic()
    }

    /// These parameters with the elastic weights changed by `f` (the paper
    /// formulations have none: they are returned unchanged).
    pub fn with_elastic(mut self, f: impl FnOnce(&mut ElasticParams)) -> Self {
        if let FormulationParams::Elastic(e) = &mut self.formulation {
            f(e);
        }
        self
    }

    /// The reading of the paper: the paper formulations' [`PaperParams::mode`];
    /// the elastic formulation is always our reading ([`Mode::Default`]).
    pub fn mode(&self) -> Mode {
        self.formulation
            .paper_params()
            .map_or(Mode::Default, |p| p.mode)
    }

    /// Rejects NaN, negative or out-of-range values, and an energy the
    /// formulation does not have.
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
        if let Some(e) = self.elastic() {
            e.validate()?;
            if !self.energy.has_elastic_form() {
                return Err(DeformError::Unsupported {
                    what: "this energy with the elastic formulation (use total or thin-plate, or formulation least_squares)",
                });
            }
            // with no stretch, no area and no Laplacian rows nothing holds
            // the free vertices' tangential positions: a singular system
            let laplacian_rows = self.lambda2 * e.laplacian > 0.0 && e.bending > 0.0;
            if e.stretch == 0.0 && e.area == 0.0 && !laplacian_rows {
                return Err(bad("stretch", e.stretch));
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
                max_iters: 7,
                formulation: FormulationParams::Elastic(ElasticParams {
                    stretch: 2.5,
                    ..ElasticParams::elastica()
                }),
                ..Params::elastica()
            }
        );
        // an explicit field equal to the other preset's does not switch it
        let c = read(r#"{"preset": "characters", "laplacian": 1.0}"#).unwrap();
        let c = c.elastic().unwrap();
        assert_eq!(c.stretch, ElasticParams::default().stretch);
        assert_eq!(c.laplacian, 1.0);
    }

    #[test]
    fn the_elastic_fields_are_read_by_the_elastic_formulation_only() {
        // a client sends one set of fields whatever the formulation: the
        // paper formulations keep none of the elastic weights, and write
        // none back, but a bad value is still refused
        let ls =
            read(r#"{"formulation": "least_squares", "bending": 0.5, "mode": "paper"}"#).unwrap();
        assert_eq!(ls.elastic(), None);
        assert_eq!(ls.mode(), Mode::Paper);
        assert_eq!(ls.formulation.kind(), Formulation::LeastSquares);
        let v = serde_json::to_value(ls).unwrap();
        assert!(v.get("bending").is_none() && v.get("stretch").is_none());
        assert_eq!(v["mode"], "paper");
        assert_eq!(serde_json::from_value::<Params>(v).unwrap(), ls);
        let bad = read(r#"{"formulation": "least_squares", "coarse_ratio": 1}"#);
        assert!(bad.unwrap_err().to_string().contains("coarse_ratio"));
        // the elastic formulation has no paper mode
        let spec = ParamsSpec {
            mode: Some(Mode::Paper),
            ..ParamsSpec::default()
        };
        assert!(matches!(
            Params::try_from(spec),
            Err(DeformError::Unsupported { .. })
        ));
        // the elastic formulation writes its mode: the editor reads it
        let v = serde_json::to_value(Params::default()).unwrap();
        assert_eq!(v["mode"], "default");
        assert_eq!(v["stretch"], DEFAULT_STRETCH);
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
