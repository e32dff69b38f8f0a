//! The Khronos glTF-Validator (the `gltf-validator` npm package, installed in
//! `web/node_modules` by `npm ci` in `web/`, which `scripts/test-web.sh
//! --install-only` and `.ci/run` do), run with Node.js.
//!
//! Where node or the package is missing the caller skips, recorded with
//! [`crate::record_skip`]; under `CI=true` a missing validator is a failure.

use std::path::PathBuf;
use std::process::Command;

/// The validator's counts and first messages.
#[derive(Debug)]
pub struct Report {
    /// Severity-0 issues.
    pub errors: u64,
    /// Severity-1 issues.
    pub warnings: u64,
    /// The first issues, as JSON text (for assertion messages).
    pub messages: String,
}

fn package() -> PathBuf {
    crate::repo_root().join("web/node_modules/gltf-validator")
}

const SCRIPT: &str = r#"
const v = require(process.argv[1]);
const bytes = new Uint8Array(require('fs').readFileSync(process.argv[2]));
v.validateBytes(bytes, {uri: process.argv[2], maxIssues: 20}).then(r => {
  console.log(JSON.stringify({errors: r.issues.numErrors, warnings: r.issues.numWarnings,
                              messages: r.issues.messages}));
}, e => { console.error(String(e)); process.exit(3); });
"#;

/// Validates `bytes` (GLB or self-contained `.gltf`); None when the
/// validator is absent outside CI (the skip is recorded).
pub fn validate(bytes: &[u8], name: &str) -> Option<Report> {
    let pkg = package();
    let node_ok = Command::new("node")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !node_ok || !pkg.join("package.json").is_file() {
        let why = format!(
            "gltf-validator not installed ({}; run `cd web && npm ci`)",
            if node_ok {
                "no web/node_modules/gltf-validator"
            } else {
                "no node"
            }
        );
        assert!(!crate::under_ci(), "{why}");
        crate::record_skip(&why);
        return None;
    }
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join(name);
    std::fs::write(&file, bytes).unwrap();
    let out = Command::new("node")
        .arg("-e")
        .arg(SCRIPT)
        .arg(&pkg)
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "gltf-validator failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    Some(Report {
        errors: v["errors"].as_u64().unwrap(),
        warnings: v["warnings"].as_u64().unwrap(),
        messages: v["messages"].to_string(),
    })
}
