//! The core's parameters and constraints as the protocol writes them.
//!
//! `dend-protocol` keeps its own copy of their wire shape
//! ([`dend_protocol::SessionParams`], [`dend_protocol::ConstraintsSpec`]) so
//! that clients do not link the solver; the server reads requests with the
//! core's types (`dend::deform::Params`, `dend::deform::ConstraintsSpec`) and
//! answers with the protocol's. The conversion goes through the JSON both
//! write, and the tests below keep the two shapes equal: every document one
//! side accepts, the other reads back to the same JSON.

use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::error::ApiError;

/// `value` (a core type) read as its protocol twin `U`. A failure means the
/// two shapes drifted apart: an internal error, logged.
pub(crate) fn to_wire<T: Serialize, U: DeserializeOwned>(
    what: &str,
    value: &T,
) -> Result<U, ApiError> {
    serde_json::to_value(value)
        .and_then(serde_json::from_value)
        .map_err(|e| ApiError::Internal(format!("{what} as the protocol writes them: {e}")))
}

/// The core's constraints as the protocol writes them.
pub(crate) fn constraints(
    spec: &dend::deform::ConstraintsSpec,
) -> Result<dend_protocol::ConstraintsSpec, ApiError> {
    to_wire("constraints", spec)
}

/// The core's parameters as the protocol writes them (every field
/// explicit).
pub(crate) fn params(p: &dend::deform::Params) -> Result<dend_protocol::SessionParams, ApiError> {
    to_wire("parameters", p)
}

/// A warning about the core's constraints as the protocol writes it: its
/// `code` and details, and its `message`.
pub(crate) fn warning(
    w: &dend::deform::ConstraintWarning,
) -> Result<dend_protocol::ConstraintWarning, ApiError> {
    Ok(dend_protocol::ConstraintWarning {
        kind: to_wire("constraint warning", w)?,
        message: w.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use dend::deform::{ConstraintsSpec, Params, ParamsSpec, Preset};
    use serde_json::{json, Value};

    /// `v` without its `null` members (the core's `ParamsSpec` writes an
    /// unset field as `null`, the protocol leaves it out; both read either
    /// as unset only when absent).
    fn without_nulls(v: Value) -> Value {
        match v {
            Value::Object(m) => Value::Object(
                m.into_iter()
                    .filter(|(_, v)| !v.is_null())
                    .map(|(k, v)| (k, without_nulls(v)))
                    .collect(),
            ),
            Value::Array(a) => Value::Array(a.into_iter().map(without_nulls).collect()),
            other => other,
        }
    }

    /// Reads `doc` with both types: both accept it and write the same JSON
    /// back, or both refuse it.
    fn same<Core, Wire>(doc: &Value) -> bool
    where
        Core: Serialize + DeserializeOwned,
        Wire: Serialize + DeserializeOwned,
    {
        let core = serde_json::from_value::<Core>(doc.clone());
        let wire = serde_json::from_value::<Wire>(doc.clone());
        match (core, wire) {
            (Ok(c), Ok(w)) => {
                let (c, w) = (serde_json::to_value(c), serde_json::to_value(w));
                let c = without_nulls(c.expect("core json"));
                assert_eq!(c, w.expect("wire json"), "{doc}");
                true
            }
            (Err(_), Err(_)) => false,
            (c, w) => panic!(
                "{doc}: core {:?}, protocol {:?}",
                c.map(|_| ()),
                w.map(|_| ())
            ),
        }
    }

    #[test]
    fn constraints_read_alike_by_the_core_and_the_protocol() {
        let accepted = [
            json!({}),
            json!({"fixed": [0, 1], "handles": [{"name": "h", "vertices": [5, 6]}]}),
            json!({"fixed": {"box": {"min": [0, 0, 0], "max": [1, 1, 0.5]}},
                "fixed_positions": [[0, 0, 0]],
                "handles": [{"vertices": {"sphere": {"center": [0, 0, 1], "radius": 0.5}},
                    "translate": [0, 0, 1], "pivot": [0, 0, 0.5],
                    "rotate": {"axis": [1, 0, 0], "degrees": 30},
                    "positions": [[1, 2, 3]]}]}),
            json!({"handles": [{"vertices": {"group": "LeftArm"}, "rotate": {"quaternion": [0, 0, 0, 1]}},
                {"vertices": {"group": {"node": 3}}, "rotate": {"quaternion_wxyz": [1, 0, 0, 0]}},
                {"vertices": {"group": {"mesh": "Body"}}},
                {"vertices": {"group": {"primitive": ["Body", 1]}}},
                {"vertices": {"joint": "hand.L", "with_children": true}},
                {"vertices": {"joint": 2}}]}),
            json!({"fixed": [], "handles": [{"vertices": [1], "translate": null}]}),
        ];
        for doc in &accepted {
            assert!(
                same::<ConstraintsSpec, dend_protocol::ConstraintsSpec>(doc),
                "{doc}"
            );
        }
        let refused = [
            json!({"fixed": [0], "extra": true}),
            json!({"handles": [{"name": "h"}]}),
            json!({"handles": [{"vertices": [1], "scale": 2}]}),
            json!({"fixed": {"box": {"min": [0, 0, 0]}}}),
            json!({"fixed": {"group": "a", "joint": "b"}}),
            json!({"fixed": [-1]}),
            json!({"handles": [{"vertices": [1], "rotate": {"axis": [1, 0, 0]}}]}),
            json!([0, 1]),
        ];
        for doc in &refused {
            assert!(
                !same::<ConstraintsSpec, dend_protocol::ConstraintsSpec>(doc),
                "{doc}"
            );
        }
    }

    #[test]
    fn every_constraint_warning_is_written_as_the_core_writes_it() {
        use dend::deform::ConstraintWarning as W;
        for w in [
            W::NothingFixed,
            W::UnconstrainedComponent {
                component: 2,
                vertices: 40,
            },
            W::StrayVertices {
                count: 3,
                vertices: vec![4, 9, 11],
            },
        ] {
            let mut core = serde_json::to_value(&w).expect("core json");
            core["message"] = w.to_string().into();
            let wire = warning(&w).expect("to the protocol");
            assert!(!matches!(wire.kind, dend_protocol::WarningKind::Other));
            assert_eq!(serde_json::to_value(&wire).expect("wire json"), core);
            let back: dend_protocol::ConstraintWarning =
                serde_json::from_value(core).expect("read back");
            assert_eq!(back, wire);
        }
        // a newer server's warning is kept as `Other`, with its message
        let newer: dend_protocol::ConstraintWarning =
            serde_json::from_value(json!({"code": "thin_handle", "message": "m", "width": 1}))
                .expect("an unknown code");
        assert_eq!(newer.kind, dend_protocol::WarningKind::Other);
        assert_eq!(newer.message, "m");
    }

    #[test]
    fn generated_shapes_read_alike_by_the_core_and_the_protocol() {
        use dend::mesh::gen::ShapeSpec;
        // (an unknown shape name is the one difference: the protocol keeps
        // the name as a string, the server refuses it)
        let accepted = [
            json!({"shape": "bar"}),
            json!({"shape": "bumpy-plane", "params": {"amplitude": 0.2}}),
            json!({"shape": "torus", "params": {"nu": 8, "nv": 6, "size": 2.0, "size2": 0.3}}),
            json!({"shape": "limb", "params": {"nu": 0}}),
        ];
        for doc in &accepted {
            assert!(same::<ShapeSpec, dend_protocol::GenerateMesh>(doc), "{doc}");
        }
        let refused = [
            json!({"shape": "bar", "extra": 1}),
            json!({"shape": "bar", "params": {"bogus": 1}}),
            json!({"shape": "bar", "params": {"nu": -1}}),
            json!({"params": {}}),
        ];
        for doc in &refused {
            assert!(
                !same::<ShapeSpec, dend_protocol::GenerateMesh>(doc),
                "{doc}"
            );
        }
    }

    #[test]
    fn parameters_read_alike_by_the_core_and_the_protocol() {
        // every preset's parameters as the server writes them (presets list)
        for p in Preset::ALL {
            let written = params(&p.params()).expect("to the protocol");
            let back: Params = serde_json::from_value(serde_json::to_value(&written).unwrap())
                .expect("the core reads the protocol's");
            assert_eq!(back, p.params(), "{}", p.name());
        }
        let accepted = [
            json!({}),
            json!({"preset": "elastica", "stretch": 2.5, "max_iters": 7}),
            json!({"energy": {"combined": {"ks": 1.0, "kb": 2.0}}, "detail": "linear",
                "formulation": "least_squares", "mode": "paper", "lambda1": 0.5}),
            json!({"energy": "thin-plate", "corrections": "while-faster", "coarse_ratio": 4,
                "correction_period": 3, "area": 0.1, "laplacian": 1.0, "bending": 2.0,
                "anderson": 0, "tol": 1e-4, "lambda2": 1.0}),
            json!({"energy": "total-paper", "formulation": "square_lu"}),
        ];
        for doc in &accepted {
            assert!(
                same::<ParamsSpec, dend_protocol::SessionParams>(doc),
                "{doc}"
            );
        }
        let refused = [
            json!({"stiffness": 1}),
            json!({"tol": null}),
            json!({"energy": "elastic"}),
            json!({"formulation": "eq24"}),
            json!({"corrections": "always"}),
            json!({"max_iters": -1}),
        ];
        for doc in &refused {
            assert!(
                !same::<ParamsSpec, dend_protocol::SessionParams>(doc),
                "{doc}"
            );
        }
    }
}
