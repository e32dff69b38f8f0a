//! The formulations the solver iterates and their modes: the enums and
//! the per-formulation parameters that [`Params`](super::Params) holds.

use serde::{Deserialize, Serialize};

use super::elastic::ElasticParams;

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
