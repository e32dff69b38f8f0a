//! The solver parameters as they travel: a session's `params` (`POST
//! /v1/sessions`) and each preset's of `GET /v1/presets` ([`SessionParams`]).
//!
//! This is the wire shape of the core's `dend::deform::ParamsSpec` (a
//! preset and any overrides, unknown fields refused, `null` refused rather
//! than read as "unset"), kept here so that a client does not link the
//! solver. The server reads the same JSON into the core's type; a test of
//! the server (`crates/server/src/wire.rs`) keeps the two shapes equal.

use serde::{Deserialize, Deserializer, Serialize};

/// The internal (elastic) energy: `total` (the default), `total-paper`,
/// `thin-plate`, `membrane`, or `{"combined": {"ks": …, "kb": …}}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Energy {
    /// `E_M`: `A = L`.
    Membrane,
    /// `E_B`: `A = L²`.
    ThinPlate,
    /// `E_C`: `A = k_s L + k_b L²`.
    Combined {
        /// Stretching weight `k_s`.
        ks: f64,
        /// Bending weight `k_b`.
        kb: f64,
    },
    /// `E_T`, `A = L² − 2 G L` (the default).
    #[serde(rename = "total")]
    TotalCurvature,
    /// The paper's table read literally, `A = L² − 2 L G`.
    #[serde(rename = "total-paper")]
    TotalCurvaturePaper,
}

/// How the detail term's target is computed: `linear` or `nonlinear`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DetailTerm {
    /// One linear solve, no local rotations.
    Linear,
    /// Re-estimated every iteration (the default).
    Nonlinear,
}

/// Which reading of the paper the paper formulations follow: `default` or
/// `paper`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Mode {
    /// Our reading (the only one of the elastic formulation).
    Default,
    /// The paper read literally.
    Paper,
}

/// The system the iteration solves: `elastic` (the default),
/// `least_squares`, `square` or `square_lu`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Formulation {
    /// The elastic energy in rotated frames.
    Elastic,
    /// Eq. (24)'s weighted least squares.
    LeastSquares,
    /// Eq. (23)'s square system, symmetric approximate Jacobian.
    Square,
    /// Eq. (23) with a sparse LU factor.
    SquareLu,
}

/// When the elastic iteration's coarse corrections stop: `while-faster` or
/// `while-gaining`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Corrections {
    /// Once one gains less than the fine iterations before it did.
    WhileFaster,
    /// Once one gains nothing.
    WhileGaining,
}

/// Session parameters: an optional preset (its name, as `GET /v1/presets`
/// lists them) and any fields that override it; every field absent is the
/// preset's. The server answers values out of range with
/// `invalid_params`. [`SessionParams::default()`] is the default preset.
///
/// `api/openapi.yaml` (`Params`) describes each field.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SessionParams {
    /// The base parameters (`characters`, `elastica`, …).
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub preset: Option<String>,
    /// The internal energy.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub energy: Option<Energy>,
    /// Soft-constraint weight `λ1` (`0`: hard constraints).
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub lambda1: Option<f64>,
    /// Detail-term weight `λ2`.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub lambda2: Option<f64>,
    /// Linear or nonlinear detail term.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub detail: Option<DetailTerm>,
    /// The paper formulations' reading.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub mode: Option<Mode>,
    /// Convergence tolerance, relative to the mean edge length.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub tol: Option<f64>,
    /// Iteration limit per solve.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub max_iters: Option<usize>,
    /// Anderson acceleration window (`0`: off).
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub anderson: Option<usize>,
    /// The system the iteration solves.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub formulation: Option<Formulation>,
    /// The elastic formulation's stretch weight `k_s`.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub stretch: Option<f64>,
    /// The elastic formulation's bending weight `β`.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub bending: Option<f64>,
    /// The elastic formulation's area weight `k_a`.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub area: Option<f64>,
    /// The elastic formulation's Laplacian weight `k_L`.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub laplacian: Option<f64>,
    /// Fine vertices per coarse vertex of the two-level iteration.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub coarse_ratio: Option<usize>,
    /// When the coarse corrections stop.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub corrections: Option<Corrections>,
    /// Fine iterations between two coarse corrections.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "present")]
    pub correction_period: Option<usize>,
}

impl SessionParams {
    /// The preset `name`'s parameters, nothing overridden.
    pub fn preset(name: &str) -> Self {
        SessionParams {
            preset: Some(name.to_owned()),
            ..SessionParams::default()
        }
    }
}

/// Reads a field that is present: `null` is refused rather than read as
/// "unset" (JavaScript writes NaN as `null`), as the server does.
fn present<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    T::deserialize(d).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_is_an_empty_object_and_fields_given_are_written() {
        let empty = serde_json::to_value(SessionParams::default()).expect("json");
        assert_eq!(empty, serde_json::json!({}));
        let p = SessionParams {
            energy: Some(Energy::Combined { ks: 1.0, kb: 2.0 }),
            max_iters: Some(7),
            corrections: Some(Corrections::WhileFaster),
            ..SessionParams::preset("elastica")
        };
        let text = serde_json::to_string(&p).expect("json");
        assert_eq!(
            serde_json::from_str::<serde_json::Value>(&text).expect("value"),
            serde_json::json!({"preset": "elastica", "energy": {"combined": {"ks": 1.0, "kb": 2.0}},
                "max_iters": 7, "corrections": "while-faster"})
        );
        assert_eq!(
            serde_json::from_str::<SessionParams>(&text).expect("back"),
            p
        );
    }

    #[test]
    fn null_and_unknown_fields_are_refused() {
        for bad in [
            r#"{"tol": null}"#,
            r#"{"preset": null}"#,
            r#"{"stiffness": 1}"#,
        ] {
            assert!(serde_json::from_str::<SessionParams>(bad).is_err(), "{bad}");
        }
    }
}
