//! The parameters as they travel: named [`Preset`]s, and the flat
//! [`ParamsSpec`] of a client's JSON (a preset and any overrides), mapped
//! into the typed [`Params`] at the edge and written back flat.

use serde::{Deserialize, Serialize};

use super::{
    Corrections, DetailTerm, ElasticParams, Formulation, FormulationParams, Mode, PaperParams,
    Params,
};
use crate::deform::energy::Energy;
use crate::deform::DeformError;

/// A named set of parameters: what the API's `"preset"` and the CLI's
/// `--preset` name. Explicit fields override a preset's.
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
    /// Overrides [`PaperParams::mode`] (the paper formulations; only
    /// `default` is accepted with the elastic one).
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
    /// Overrides the formulation ([`FormulationParams::kind`]).
    #[serde(deserialize_with = "present")]
    pub formulation: Option<Formulation>,
    /// Overrides [`ElasticParams::stretch`] (read by the elastic formulation
    /// only; checked whatever the formulation).
    #[serde(deserialize_with = "present")]
    pub stretch: Option<f64>,
    /// Overrides [`ElasticParams::bending`] (read by the elastic formulation
    /// only; checked whatever the formulation).
    #[serde(deserialize_with = "present")]
    pub bending: Option<f64>,
    /// Overrides [`ElasticParams::area`] (read by the elastic formulation
    /// only; checked whatever the formulation).
    #[serde(deserialize_with = "present")]
    pub area: Option<f64>,
    /// Overrides [`ElasticParams::laplacian`] (read by the elastic formulation
    /// only; checked whatever the formulation).
    #[serde(deserialize_with = "present")]
    pub laplacian: Option<f64>,
    /// Overrides [`ElasticParams::coarse_ratio`] (read by the elastic formulation
    /// only; checked whatever the formulation).
    #[serde(deserialize_with = "present")]
    pub coarse_ratio: Option<usize>,
    /// Overrides [`ElasticParams::corrections`] (read by the elastic formulation
    /// only; checked whatever the formulation).
    #[serde(deserialize_with = "present")]
    pub corrections: Option<Corrections>,
    /// Overrides [`ElasticParams::correction_period`] (read by the elastic formulation
    /// only; checked whatever the formulation).
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
