//! The internal energies (design.md §3; paper table in §5): what each one
//! is, and everything the formulations need to know about its operator, in
//! one place. A new energy is one new variant here and its arms below; the
//! assembly ([`super::system`], [`super::square`]), the matrix-free rows
//! ([`super::stacked`]), the elastic weights and the factor key only call
//! these methods.

use serde::{Deserialize, Serialize};
use sprs::CsMat;

use crate::mesh::Real;
use crate::operators::Operators;
use dend_linalg::sparse::{matmul, scale_and_shift_diagonal, scale_entries};

/// The internal (elastic) energy, i.e. the matrix `A` of the term `A (X' - X)`
/// (design.md §3; paper table in §5).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Energy {
    /// `E_M`, paper eq. (10): `A = L`.
    Membrane,
    /// `E_B`, paper eq. (9): `A = L²`.
    ThinPlate,
    /// `E_C`, paper eq. (11): `A = k_s L + k_b L²`.
    Combined {
        /// Stretching weight `k_s`.
        ks: f64,
        /// Bending weight `k_b`.
        kb: f64,
    },
    /// `E_T`, paper eq. (12) derived through `H n ≈ (L X)/2`: `A = L² - 2 G L`
    /// (translation invariant: `G L 1 = 0`). The default.
    #[default]
    #[serde(rename = "total")]
    TotalCurvature,
    /// The paper's table read literally: `A = L² - 2 L G` (not translation
    /// invariant, since `L G 1 ≠ 0`; kept for comparison).
    #[serde(rename = "total-paper")]
    TotalCurvaturePaper,
}

impl Energy {
    /// Parses the CLI spelling: `total`, `total-paper`, `thin-plate`,
    /// `membrane`, `combined` (with `k_s = k_b = 1`).
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "total" | "total-curvature" => Energy::TotalCurvature,
            "total-paper" | "total-curvature-paper" => Energy::TotalCurvaturePaper,
            "thin-plate" => Energy::ThinPlate,
            "membrane" => Energy::Membrane,
            "combined" => Energy::Combined { ks: 1.0, kb: 1.0 },
            _ => return None,
        })
    }

    /// The cache-key code of the energy: a tag and its weights' bits (two
    /// equal codes give the same matrix).
    pub(crate) fn key(self) -> (u8, u64, u64) {
        match self {
            Energy::Membrane => (0, 0, 0),
            Energy::ThinPlate => (1, 0, 0),
            Energy::Combined { ks, kb } => (2, ks.to_bits(), kb.to_bits()),
            Energy::TotalCurvature => (3, 0, 0),
            Energy::TotalCurvaturePaper => (4, 0, 0),
        }
    }

    /// How the energy's matrix `A` factors through `L` ([`Shape`]).
    pub(crate) fn shape(self) -> Shape {
        match self {
            Energy::Membrane => Shape::Left {
                ci: 1.0,
                cl: 0.0,
                g: 0.0,
            },
            Energy::ThinPlate => Shape::Left {
                ci: 0.0,
                cl: 1.0,
                g: 0.0,
            },
            Energy::Combined { ks, kb } => Shape::Left {
                ci: ks,
                cl: kb,
                g: 0.0,
            },
            Energy::TotalCurvature => Shape::Left {
                ci: 0.0,
                cl: 1.0,
                g: 1.0,
            },
            Energy::TotalCurvaturePaper => Shape::Right,
        }
    }

    /// Whether the elastic formulation minimises this energy: its bending
    /// energy is total curvature or thin plate, in our reading (the others
    /// belong to the paper's formulations).
    pub fn has_elastic_form(self) -> bool {
        match self {
            Energy::TotalCurvature | Energy::ThinPlate => true,
            Energy::Membrane | Energy::Combined { .. } | Energy::TotalCurvaturePaper => false,
        }
    }

    /// The weight of the Gaussian-curvature part `−2 G L` of the elastic
    /// formulation's bending energy, as a share of `k_b`: 1 for total
    /// curvature, 0 for thin plate (the elastic formulation takes no other
    /// energy, see [`Energy::has_elastic_form`]).
    pub(crate) fn gaussian_share(self) -> Real {
        match self {
            Energy::TotalCurvature | Energy::TotalCurvaturePaper => 1.0,
            Energy::Membrane | Energy::ThinPlate | Energy::Combined { .. } => 0.0,
        }
    }

    /// The energy matrix `A`, `#V×#V`, CSR.
    ///
    /// Each `A` with `L²` in it is one sparse product `P L` (or `L P`), never
    /// a sum of products: `k_s L + k_b L² = (k_s I + k_b L) L`,
    /// `L² − 2GL = (L − 2G) L` (eq. (12) as design.md §3 reads it) and the paper's
    /// literal `L² − 2LG = L (L − 2G)`. A product keeps every structural
    /// entry of the sum, also where its terms cancel.
    pub fn matrix(self, ops: &Operators) -> CsMat<Real> {
        let l = &ops.l;
        match self {
            Energy::Membrane => l.clone(),
            Energy::ThinPlate => matmul(l, l),
            Energy::Combined { ks, kb } => matmul(&scale_and_shift_diagonal(l, kb, |_| ks), l),
            Energy::TotalCurvature => {
                matmul(&scale_and_shift_diagonal(l, 1.0, |i| -2.0 * ops.g[i]), l)
            }
            Energy::TotalCurvaturePaper => {
                matmul(l, &scale_and_shift_diagonal(l, 1.0, |i| -2.0 * ops.g[i]))
            }
        }
    }

    /// The eq. (23) internal term over all vertices (see [`super::square`]):
    /// `(D⁻¹ P L` exact, its symmetric positive semi-definite stand-in`)`.
    pub(crate) fn square_operators(self, ops: &Operators) -> (CsMat<Real>, CsMat<Real>) {
        let lbar = &ops.lbar;
        let neg_lbar = || lbar.map(|v| -v);
        let ldl = || matmul(lbar, &ops.l); // Lbar D Lbar
        let g = &ops.g;
        // 2 G^{1/2} (−Lbar) G^{1/2}
        let g_sym = || scale_entries(lbar, |i, j| -2.0 * (g[i] * g[j]).sqrt());
        match self {
            Energy::Membrane => (neg_lbar(), neg_lbar()),
            Energy::ThinPlate => (ldl(), ldl()),
            Energy::Combined { ks, kb } => {
                let k = &neg_lbar().map(|v| ks * v) + &ldl().map(|v| kb * v);
                (k.clone(), k)
            }
            Energy::TotalCurvature => {
                let ldl = ldl();
                let g_lbar = scale_entries(lbar, |i, _| -2.0 * g[i]); // −2 G Lbar
                (&ldl + &g_lbar, &ldl + &g_sym())
            }
            Energy::TotalCurvaturePaper => {
                let ldl = ldl();
                let lbar_g = scale_entries(lbar, |_, j| -2.0 * g[j]); // −2 Lbar G
                (&ldl + &lbar_g, &ldl + &g_sym())
            }
        }
    }
}

/// The energy matrix `A` of design.md §3 ([`Energy::matrix`]).
pub fn energy_matrix(ops: &Operators, energy: Energy) -> CsMat<Real> {
    energy.matrix(ops)
}

/// How an energy's `A` factors through `L` (see [`super::stacked`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Shape {
    /// `A = P L`, `P = ci I + cl L − 2 g G` (`g` 0 or 1).
    Left { ci: Real, cl: Real, g: Real },
    /// `A = L (L − 2G)` (the paper's literal `L² − 2 L G`).
    Right,
}
