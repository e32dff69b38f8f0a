//! Writes the frame fixtures of the JavaScript client's decoder test
//! (`clients/js/test/frames.test.mjs`): streams of frames of every version
//! and encoding made by this crate's encoders, malformed variants of them,
//! and the fuzz corpus of the frame decoder, each with what
//! [`FrameDecoder`] decodes from it (the header, the f32 positions bit for
//! bit, or the error). The JavaScript decoder must give the same.
//!
//! The fixtures go to `$DEND_JS_FIXTURES` (default: `js-fixtures` in
//! Cargo's test scratch folder); `manifest.json` lists them.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use dend_protocol::{
    encode_frame_v3, DecodedFrame, DeltaEncoder, FrameBody, FrameDecoder, FrameEncoding,
    FrameError, FrameHeader, LEVEL_COARSE, LEVEL_FULL,
};
use serde_json::{json, Value};

/// A flat `n × n` sheet with a bump of height `h` centred at `0.5 + t`.
fn sheet(n: usize, t: f64, h: f64) -> Vec<[f64; 3]> {
    (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 / n as f64, (i / n) as f64 / n as f64);
            let r2 = (x - 0.5 - t).powi(2) + (y - 0.5).powi(2);
            [x, y, h * (-r2 / 0.01).exp()]
        })
        .collect()
}

/// A bar along x, `m` rings of `k` vertices, bent upwards by `angle`
/// radians at its free end and twisted by `twist` (a handle drag's poses).
fn bar(m: usize, k: usize, angle: f64, twist: f64) -> Vec<[f64; 3]> {
    let mut out = Vec::with_capacity(m * k);
    for i in 0..m {
        let s = i as f64 / (m - 1) as f64;
        let a = angle * s * s;
        let (c, d) = (a.cos(), a.sin());
        let x = 4.0 * s;
        for j in 0..k {
            let phi = std::f64::consts::TAU * j as f64 / k as f64 + twist * s;
            let (y, z) = (0.3 * phi.cos(), 0.3 * phi.sin());
            out.push([x * c - z * d, y, x * d + z * c + 10.0]);
        }
    }
    out
}

/// Deterministic points in a box: xorshift64.
fn cloud(n: usize, seed: u64, scale: f64) -> Vec<[f64; 3]> {
    let mut s = seed | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| [scale * (next() - 0.5), scale * next(), -scale * next()])
        .collect()
}

fn header(revision: u64, ack_seq: u64, iteration: u32) -> FrameHeader {
    FrameHeader {
        revision,
        ack_seq,
        iteration,
        converged: false,
        settled: false,
        objective: 0.25 / f64::from(iteration + 1),
        vertex_count: 0,
        level: LEVEL_FULL,
    }
}

fn num(x: f64) -> Value {
    if x.is_nan() {
        json!("NaN")
    } else if x.is_infinite() {
        json!(if x > 0.0 { "inf" } else { "-inf" })
    } else {
        json!(x)
    }
}

fn error_json(e: &FrameError) -> Value {
    let (kind, extra) = match e {
        FrameError::Length { got, expected } => {
            ("length", json!({"got": got, "expected": expected}))
        }
        FrameError::Magic => ("magic", json!({})),
        FrameError::Version(v) => ("version", json!({"value": v})),
        FrameError::Encoding(v) => ("encoding", json!({"value": v})),
        FrameError::Level(v) => ("level", json!({"value": v})),
        FrameError::Box => ("box", json!({})),
        FrameError::Delta(_) => ("delta", json!({})),
        FrameError::Base { base, have } => ("base", json!({"base": base, "have": have})),
    };
    json!({"kind": kind, "message": e.to_string(), "details": extra})
}

/// The decoded frame as JSON, its positions' f32 bits in a file of `w`.
fn frame_json(f: &DecodedFrame, w: &mut Writer) -> Value {
    let bytes: Vec<u8> = f
        .positions
        .iter()
        .flat_map(|p| p.iter().flat_map(|x| x.to_le_bytes()))
        .collect();
    let positions = w.store(bytes, "pos");
    let h = &f.header;
    json!({
        "version": f.version,
        "encoding": f.encoding.name(),
        "level": h.level,
        "converged": h.converged,
        "settled": h.settled,
        "revision": h.revision.to_string(),
        "ack_seq": h.ack_seq.to_string(),
        "iteration": h.iteration,
        "vertex_count": h.vertex_count,
        "objective": num(h.objective),
        "bbox": f.bbox.map(|[lo, hi]| json!([lo.map(num), hi.map(num)])),
        "positions": positions,
    })
}

struct Writer {
    dir: PathBuf,
    cases: Vec<Value>,
    count: usize,
    /// Files already written, by content (a frame decoded in many cases
    /// is stored once).
    files: HashMap<Vec<u8>, String>,
}

impl Writer {
    /// The name of a file holding `bytes` (`ext`), written once.
    fn store(&mut self, bytes: Vec<u8>, ext: &str) -> String {
        let next = self.files.len();
        let dir = &self.dir;
        self.files
            .entry(bytes)
            .or_insert_with_key(|b| {
                let name = format!("f{next:05}.{ext}");
                std::fs::write(dir.join(&name), b).unwrap();
                name
            })
            .clone()
    }
}

impl Writer {
    /// Decodes `frames` with one decoder (one connection), writing each
    /// frame and what it decodes to.
    fn case(&mut self, name: &str, frames: &[Vec<u8>]) {
        let mut dec = FrameDecoder::new();
        let mut out = Vec::new();
        for b in frames {
            self.count += 1;
            let file = self.store(b.clone(), "bin");
            let expect = match dec.decode(b) {
                Ok(f) => json!({"ok": frame_json(&f, self)}),
                Err(e) => json!({"error": error_json(&e)}),
            };
            out.push(json!({"file": file, "expect": expect}));
        }
        self.cases.push(json!({"name": name, "frames": out}));
    }
}

/// Variants of a valid frame `b` (given after the frames `before` on the
/// same connection): truncations, one byte changed at every header field
/// and through the payload, a byte appended.
fn mutations(w: &mut Writer, name: &str, before: &[Vec<u8>], b: &[u8]) {
    let mut variants: Vec<(String, Vec<u8>)> = Vec::new();
    let len = b.len();
    let mut cuts = vec![
        0,
        1,
        39,
        40,
        41,
        95,
        96,
        97,
        147,
        148,
        149,
        len / 2,
        len - 2,
        len - 1,
    ];
    cuts.retain(|&c| c < len);
    cuts.dedup();
    for c in cuts {
        variants.push((format!("cut{c}"), b[..c].to_vec()));
    }
    let mut longer = b.to_vec();
    longer.push(0);
    variants.push(("plus1".into(), longer));
    // every byte of the two headers, then a stride through the payload
    let mut at: Vec<usize> = (0..len.min(152)).collect();
    at.extend((152..len).step_by(len / 17 + 1));
    for i in at {
        for x in [0x01u8, 0x80, 0xff] {
            let mut v = b.to_vec();
            v[i] ^= x;
            variants.push((format!("x{i}^{x:02x}"), v));
        }
    }
    for (tag, v) in variants {
        let mut frames = before.to_vec();
        frames.push(v);
        w.case(&format!("{name}/{tag}"), &frames);
    }
}

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn write_js_fixtures() {
    let dir = std::env::var_os("DEND_JS_FIXTURES")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_TARGET_TMPDIR")).join("js-fixtures"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut w = Writer {
        dir: dir.clone(),
        cases: Vec::new(),
        count: 0,
        files: HashMap::new(),
    };

    // version 2: the default connection's frames
    let mut v2 = Vec::new();
    for (i, pose) in [
        bar(12, 8, 0.0, 0.0),
        bar(12, 8, 0.7, 0.3),
        Vec::new(),
        cloud(50, 7, 3e4),
    ]
    .iter()
    .enumerate()
    {
        let mut h = header(10 + i as u64, i as u64, i as u32);
        h.vertex_count = pose.len() as u32;
        h.converged = i == 1;
        h.settled = i >= 1;
        if i == 2 {
            h.objective = f64::NAN;
        }
        v2.push(FrameBody::from_pose(pose).finish(&h).to_vec());
    }
    w.case("v2", &v2);

    // version 3, f32 and q16, both levels, flat boxes included
    for enc in [FrameEncoding::F32, FrameEncoding::Q16] {
        let mut frames = Vec::new();
        let poses = [
            bar(20, 10, 0.4, 0.0),
            sheet(16, 0.0, 0.0),
            sheet(16, 0.1, 0.2),
            cloud(200, 99, 1e-3),
            Vec::new(),
            vec![[1.5, -2.0, 3.25]],
        ];
        for (i, pose) in poses.iter().enumerate() {
            let mut h = header(100 + i as u64, 50 + i as u64, i as u32);
            h.level = if i % 2 == 1 { LEVEL_COARSE } else { LEVEL_FULL };
            h.settled = i == 2;
            h.converged = i == 2;
            frames.push(encode_frame_v3(&h, pose, enc).to_vec());
        }
        w.case(&format!("v3-{}", enc.name()), &frames);
    }

    // delta: a drag of the bump (prediction 1 on steady motion), a settled
    // f32 frame between runs, a vertex count change, a shrinking pose and
    // an index leaving i32 (key frames)
    let mut enc = DeltaEncoder::new();
    let mut frames = Vec::new();
    let mut rev = 200;
    let mut push_delta =
        |enc: &mut DeltaEncoder, pose: &[[f64; 3]], frames: &mut Vec<Vec<u8>>, level: u8| {
            rev += 1;
            let mut h = header(rev, rev / 2, (rev % 7) as u32);
            h.level = level;
            frames.push(enc.encode(&h, pose).to_vec());
            rev
        };
    for s in 0..12 {
        let t = 0.01 * f64::from(s);
        let level = if s < 4 { LEVEL_COARSE } else { LEVEL_FULL };
        push_delta(&mut enc, &sheet(24, t, 0.3), &mut frames, level);
    }
    let mut h = header(300, 40, 9);
    h.settled = true;
    h.converged = true;
    frames.push(encode_frame_v3(&h, &sheet(24, 0.12, 0.3), FrameEncoding::F32).to_vec());
    enc.reset();
    for s in 0..4 {
        push_delta(
            &mut enc,
            &bar(30, 12, 0.1 * f64::from(s), 0.05 * f64::from(s)),
            &mut frames,
            LEVEL_FULL,
        );
    }
    for s in 0..4 {
        // the bar shrinks to half its size: a key frame on the way
        let k = 1.0 - 0.15 * f64::from(s);
        let pose: Vec<[f64; 3]> = bar(30, 12, 0.4, 0.2)
            .iter()
            .map(|p| p.map(|x| x * k))
            .collect();
        push_delta(&mut enc, &pose, &mut frames, LEVEL_FULL);
    }
    let mut far = bar(30, 12, 0.4, 0.2);
    far[0] = [1e12, 0.0, 0.0];
    push_delta(&mut enc, &far, &mut frames, LEVEL_FULL);
    push_delta(&mut enc, &Vec::new(), &mut frames, LEVEL_FULL);
    w.case("delta", &frames);

    // a connection that loses a frame: the next ones refer to a revision
    // the decoder does not hold, until a key frame
    let mut lost = frames[..5].to_vec();
    lost.extend_from_slice(&frames[6..14]);
    w.case("delta-lost-frame", &lost);

    // malformed variants of a frame of every kind
    mutations(&mut w, "v2", &[], &v2[1]);
    let f32_frame =
        encode_frame_v3(&header(7, 1, 1), &bar(6, 5, 0.3, 0.1), FrameEncoding::F32).to_vec();
    mutations(&mut w, "v3-f32", &[], &f32_frame);
    let q16_frame =
        encode_frame_v3(&header(8, 1, 1), &bar(6, 5, 0.3, 0.1), FrameEncoding::Q16).to_vec();
    mutations(&mut w, "v3-q16", &[], &q16_frame);
    mutations(&mut w, "delta-key", &[], &frames[0]);
    mutations(&mut w, "delta-change", &frames[..5], &frames[5]);

    // the fuzz corpus of the frame decoder (one decoder per file)
    let corpus = repo_root().join("tests/data/fuzz/pose_frame");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&corpus)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    let minimised = corpus.join("corpus");
    if minimised.is_dir() {
        files.extend(
            std::fs::read_dir(minimised)
                .unwrap()
                .map(|e| e.unwrap().path()),
        );
    }
    files.sort();
    assert!(files.len() >= 5, "the fuzz corpus of pose_frame is missing");
    for f in files {
        let name = f
            .strip_prefix(repo_root())
            .unwrap_or(&f)
            .to_string_lossy()
            .replace('\\', "/");
        w.case(&format!("corpus:{name}"), &[std::fs::read(&f).unwrap()]);
    }

    let errors = w
        .cases
        .iter()
        .flat_map(|c| c["frames"].as_array().unwrap().iter())
        .filter(|f| f["expect"]["error"].is_object())
        .count();
    assert!(
        errors > 100 && w.count - errors > 50,
        "{errors} errors of {}",
        w.count
    );
    let manifest = json!({"cases": w.cases, "frames": w.count, "errors": errors});
    std::fs::write(
        dir.join("manifest.json"),
        serde_json::to_vec(&manifest).unwrap(),
    )
    .unwrap();
    eprintln!(
        "js fixtures: {} frames ({errors} malformed) in {}",
        w.count,
        dir.display()
    );
}
