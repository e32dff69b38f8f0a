//! The JSON Schema in `api/constraints.schema.json` and the serde types of
//! `ConstraintsSpec` must accept and reject the same documents. The schema is
//! checked by an independent validator (Python's `jsonschema`, from the
//! test venv).

use std::path::Path;
use std::process::Command;

use dend::deform::ConstraintsSpec;

#[test]
fn schema_and_serde_agree_on_examples_and_invalid_documents() {
    let Some(py) = dend_testkit::python_with(&["jsonschema"]) else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut docs: Vec<(String, String)> = std::fs::read_dir(root.join("examples"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "json"))
        .map(|e| {
            (
                e.path().display().to_string(),
                std::fs::read_to_string(e.path()).unwrap(),
            )
        })
        .collect();
    assert!(docs.len() >= 4, "expected the example constraint files");
    let more = [
        r#"{"fixed": [0, 1, 2]}"#,
        r#"{"fixed": {"sphere": {"center": [0,0,0], "radius": 1}}, "handles": [{"vertices": [5], "rotate": {"quaternion": [0,0,0,1]}}]}"#,
        r#"{"fixed": [0], "handles": [{"vertices": [5], "rotate": {"quaternion_wxyz": [1,0,0,0]}}]}"#,
        r#"{"fixed": [0], "handles": [{"vertices": [5], "positions": [[1,2,3]], "pivot": [0,0,0]}]}"#,
        r#"{"fixed": [0, 4], "fixed_positions": [[0,0,1], [1,0,1]]}"#,
        r#"{"fixed": {"group": "base"}, "handles": [{"vertices": {"group": {"node": "Arm"}}}]}"#,
        r#"{"fixed": {"group": {"mesh": 0}}, "handles": [{"vertices": {"group": {"primitive": ["Body", 1]}}}]}"#,
        r#"{"fixed": {"group": {"node": 2}}, "handles": [{"vertices": {"group": {"primitive": [0, 1]}}}]}"#,
        // invalid ones
        r#"{"fixed": [0], "fixed_positions": [[0,0]]}"#,
        r#"{"fixed": [0], "fixed_positions": [0, 0, 1]}"#,
        r#"{"fixed": [0], "extra": true}"#,
        r#"{"fixed": [-1]}"#,
        r#"{"fixed": [0], "handles": [{"name": "h"}]}"#,
        r#"{"fixed": [0], "handles": [{"vertices": [1], "translate": [1, 2]}]}"#,
        r#"{"fixed": [0], "handles": [{"vertices": [1], "rotate": {"axis": [0,0,1]}}]}"#,
        r#"{"fixed": {"box": {"min": [0,0,0]}}}"#,
        r#"{"fixed": {"sphere": {"center": [0,0,0], "radius": 1, "x": 2}}}"#,
        r#"{"fixed": [0], "handles": [{"vertices": [1], "oops": 1}]}"#,
        r#"{"fixed": "all"}"#,
        r#"{"fixed": {"group": 5}}"#,
        r#"{"fixed": {"group": {"o": "x"}}}"#,
        r#"{"fixed": {"group": {"node": 1, "mesh": 2}}}"#,
        r#"{"fixed": {"group": {"primitive": [0]}}}"#,
        r#"{"fixed": {"group": {"primitive": [0, -1]}}}"#,
        r#"{"fixed": {"group": "a", "extra": 1}}"#,
    ];
    for (k, d) in more.iter().enumerate() {
        docs.push((format!("inline #{k}"), d.to_string()));
    }
    let schema = root.join("api/constraints.schema.json");
    let script = r#"
import json, sys, jsonschema
schema = json.load(open(sys.argv[1]))
jsonschema.Draft202012Validator.check_schema(schema)
v = jsonschema.Draft202012Validator(schema)
for line in sys.stdin:
    doc = json.loads(line)
    print("ok" if v.is_valid(doc) else "invalid")
"#;
    let input: String = docs
        .iter()
        .map(|(_, d)| {
            serde_json::to_string(&serde_json::from_str::<serde_json::Value>(d).unwrap()).unwrap()
                + "\n"
        })
        .collect();
    let mut child = Command::new(&py)
        .args(["-c", script, schema.to_str().unwrap()])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "schema check failed");
    let verdicts: Vec<String> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    assert_eq!(verdicts.len(), docs.len());
    let mut invalid = 0;
    for ((name, doc), verdict) in docs.iter().zip(&verdicts) {
        let serde_ok = serde_json::from_str::<ConstraintsSpec>(doc).is_ok();
        assert_eq!(
            serde_ok,
            verdict == "ok",
            "{name}: serde says {serde_ok}, schema says {verdict}: {doc}"
        );
        invalid += (!serde_ok) as usize;
    }
    assert_eq!(
        invalid, 17,
        "the invalid documents must be rejected by both"
    );
}
