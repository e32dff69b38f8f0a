//! The typed [`Params`] every solver reads, and their mapping from and to
//! the flat [`ParamsSpec`] of the wire (the preset's parameters, then the
//! overrides): the file is above `spec.rs`, whose types name no `Params`.

use serde::{Deserialize, Serialize};

use super::elastic::ElasticParams;
use super::formulation::{DetailTerm, Formulation, FormulationParams, Mode, PaperParams};
use super::spec::{ParamsSpec, Preset};
use crate::deform::energy::Energy;
use crate::deform::error::DeformError;

/// Every solver parameter, with documented defaults: those every
/// formulation reads, and the formulation with its own.
///
/// Read from JSON through [`ParamsSpec`]: a `"preset"` names the base
/// ([`Preset`], the default's when absent) and every field given overrides
/// it. Written out, every field is explicit (no preset), so a stored
/// session keeps its parameters when a default changes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ParamsSpec", into = "WrittenParams")]
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
        if self.anderson > crate::deform::anderson::MAX_WINDOW {
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

impl Preset {
    /// The preset's parameters.
    pub fn params(self) -> Params {
        match self {
            Preset::Characters => Params::default(),
            Preset::Elastica => Params::elastica(),
        }
    }
}

impl TryFrom<ParamsSpec> for Params {
    type Error = DeformError;

    /// The preset's parameters with the spec's overrides. The elastic
    /// weights are read (and checked, as they always were) whatever the
    /// formulation, and kept only by the elastic one: a client may send
    /// one set of fields for every formulation. The paper mode with the
    /// elastic formulation is refused ([`DeformError::Unsupported`]).
    fn try_from(s: ParamsSpec) -> Result<Params, DeformError> {
        let b = s.preset.unwrap_or_default().params();
        let e = b.elastic().copied().unwrap_or_default();
        let elastic = ElasticParams {
            stretch: s.stretch.unwrap_or(e.stretch),
            bending: s.bending.unwrap_or(e.bending),
            area: s.area.unwrap_or(e.area),
            laplacian: s.laplacian.unwrap_or(e.laplacian),
            coarse_ratio: s.coarse_ratio.unwrap_or(e.coarse_ratio),
            corrections: s.corrections.unwrap_or(e.corrections),
            correction_period: s.correction_period.unwrap_or(e.correction_period),
        };
        let paper = PaperParams {
            mode: s.mode.unwrap_or(b.mode()),
        };
        let formulation = match s.formulation.unwrap_or(b.formulation.kind()) {
            Formulation::Elastic if paper.mode == Mode::Paper => {
                return Err(DeformError::Unsupported {
                    what: "the paper mode with the elastic formulation (use formulation least_squares)",
                });
            }
            Formulation::Elastic => FormulationParams::Elastic(elastic),
            other => {
                elastic.validate()?;
                FormulationParams::paper(other, paper)
            }
        };
        Ok(Params {
            energy: s.energy.unwrap_or(b.energy),
            lambda1: s.lambda1.unwrap_or(b.lambda1),
            lambda2: s.lambda2.unwrap_or(b.lambda2),
            detail: s.detail.unwrap_or(b.detail),
            tol: s.tol.unwrap_or(b.tol),
            max_iters: s.max_iters.unwrap_or(b.max_iters),
            anderson: s.anderson.unwrap_or(b.anderson),
            formulation,
        })
    }
}

/// [`Params`] as written: every field explicit (no preset), the elastic
/// weights only with the elastic formulation.
#[derive(Serialize)]
pub(super) struct WrittenParams {
    energy: Energy,
    lambda1: f64,
    lambda2: f64,
    detail: DetailTerm,
    mode: Mode,
    tol: f64,
    max_iters: usize,
    anderson: usize,
    formulation: Formulation,
    #[serde(flatten)]
    elastic: Option<ElasticParams>,
}

impl From<Params> for WrittenParams {
    fn from(p: Params) -> Self {
        WrittenParams {
            energy: p.energy,
            lambda1: p.lambda1,
            lambda2: p.lambda2,
            detail: p.detail,
            mode: p.mode(),
            tol: p.tol,
            max_iters: p.max_iters,
            anderson: p.anderson,
            formulation: p.formulation.kind(),
            elastic: p.elastic().copied(),
        }
    }
}
