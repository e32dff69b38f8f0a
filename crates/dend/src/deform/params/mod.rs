//! Solver parameters: energy, constraint weights, detail term, and the
//! formulation with the parameters only it reads (design.md §1, §3).

mod elastic;
mod formulation;
mod spec;
mod typed;

pub use elastic::{
    Corrections, ElasticParams, DEFAULT_AREA, DEFAULT_BENDING, DEFAULT_COARSE_RATIO,
    DEFAULT_CORRECTION_PERIOD, DEFAULT_LAPLACIAN, DEFAULT_STRETCH, ELASTICA_COARSE_RATIO,
    ELASTICA_CORRECTION_PERIOD, ELASTICA_LAPLACIAN, ELASTICA_STRETCH,
};
pub use formulation::{DetailTerm, Formulation, FormulationParams, Mode, PaperParams};
pub use spec::{ParamsSpec, Preset};
pub use typed::Params;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deform::error::DeformError;

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
