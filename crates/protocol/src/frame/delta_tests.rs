use super::*;
use crate::frame::{FrameDecoder, LEVEL_FULL};
use proptest::prelude::*;

fn header(revision: u64) -> FrameHeader {
    FrameHeader {
        revision,
        ack_seq: 3,
        iteration: 1,
        converged: false,
        settled: false,
        objective: 2.0,
        vertex_count: 0,
        level: LEVEL_FULL,
    }
}

fn diagonal(p: &[[f64; 3]]) -> f64 {
    let [lo, hi] = bounding_box(p);
    (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
}

fn max_dist(a: &[[f64; 3]], b: &[[f32; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            (0..3)
                .map(|k| (p[k] - f64::from(q[k])).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
}

/// A flat grid of `n × n` points, a bump of height `h` moved by `t`.
fn sheet(n: usize, t: f64, h: f64) -> Vec<[f64; 3]> {
    (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 / n as f64, (i / n) as f64 / n as f64);
            let r2 = (x - 0.5 - t).powi(2) + (y - 0.5).powi(2);
            [x, y, h * (-r2 / 0.01).exp()]
        })
        .collect()
}

#[test]
fn zigzag_round_trips_at_the_extremes() {
    for d in [0, 1, -1, 63, -64, 64, i32::MAX, i32::MIN] {
        assert_eq!(unzigzag(zigzag(d)), d);
    }
    assert_eq!(zigzag(-1), 1);
    assert_eq!(zigzag(1), 2);
    let mut v = Vec::new();
    put_varint(&mut v, u32::MAX);
    assert_eq!(v, [0xff, 0xff, 0xff, 0xff, 0x0f]);
    for z in [
        0,
        1,
        127,
        128,
        16383,
        16384,
        1 << 21,
        (1 << 28) - 1,
        1 << 28,
        u32::MAX,
    ] {
        let mut v = Vec::new();
        put_varint(&mut v, z);
        assert_eq!(varint_len(z), v.len(), "{z}");
    }
}

/// A steady turn costs less with prediction 1 (the change minus the
/// previous change), which the encoder picks, and decodes the same.
#[test]
fn a_steady_motion_is_predicted() {
    let n = 100;
    let mut enc = DeltaEncoder::new();
    let mut dec = FrameDecoder::new();
    let mut sizes = vec![];
    let rest = sheet(n, 0.0, 0.1);
    for (r, t) in (1..).zip([0.0, 0.01, 0.02, 0.03, 0.04]) {
        let (s, c) = f64::sin_cos(t);
        let p: Vec<[f64; 3]> = rest
            .iter()
            .map(|p| [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]])
            .collect();
        let b = enc.encode(&header(r), &p);
        sizes.push((b[97], b.len()));
        let f = dec.decode(&b).unwrap();
        assert!(max_dist(&p, &f.positions) <= 1.4723 * diagonal(&p) / DELTA_GRID_DIVISIONS);
    }
    assert_eq!(sizes[1].0, 0, "nothing to extrapolate after a key frame");
    assert!(sizes[2..].iter().all(|s| s.0 == 1), "{sizes:?}");
    assert!(sizes[2..].iter().all(|s| s.1 < sizes[1].1), "{sizes:?}");
}

/// What did not move costs about nothing, what moved costs bytes: a
/// repeated pose of 40,000 vertices is a few hundred bytes, a local bump
/// moving across it far less than `q16`'s 6 bytes per vertex.
#[test]
fn the_bytes_follow_what_moved() {
    let n = 200;
    let mut enc = DeltaEncoder::new();
    let mut dec = FrameDecoder::new();
    let p0 = sheet(n, 0.0, 0.1);
    let key = enc.encode(&header(1), &p0);
    assert_eq!(key[96], 1, "the first frame is a key frame");
    let same = enc.encode(&header(2), &p0);
    assert_eq!(same[96], 0);
    // 120,000 zero bytes deflate to a few hundred (runs of 258 at most)
    assert!(
        same.len() < 1200,
        "an unchanged pose took {} bytes",
        same.len()
    );
    let p1 = sheet(n, 0.01, 0.1);
    let moved = enc.encode(&header(3), &p1);
    let q16 = crate::frame::encode_frame_v3(&header(3), &p1, FrameEncoding::Q16).len();
    assert!(
        moved.len() * 10 < q16,
        "a moving bump: {} bytes against q16's {q16}",
        moved.len()
    );
    for (b, p) in [(&key, &p0), (&same, &p0), (&moved, &p1)] {
        let f = dec.decode(b).unwrap();
        assert_eq!(f.encoding, FrameEncoding::Delta);
        assert!(max_dist(p, &f.positions) <= 1.4723 * diagonal(&p0) / DELTA_GRID_DIVISIONS);
    }
}

#[test]
fn a_frame_against_another_base_is_refused_and_a_key_frame_recovers() {
    let mut enc = DeltaEncoder::new();
    let p = sheet(10, 0.0, 0.1);
    let k = enc.encode(&header(5), &p);
    let d6 = enc.encode(&header(6), &sheet(10, 0.1, 0.1));
    let d7 = enc.encode(&header(7), &sheet(10, 0.2, 0.1));
    let mut dec = FrameDecoder::new();
    assert_eq!(
        dec.decode(&d6),
        Err(FrameError::Base {
            base: 5,
            have: None
        })
    );
    dec.decode(&k).unwrap();
    assert_eq!(
        dec.decode(&d7),
        Err(FrameError::Base {
            base: 6,
            have: Some(5)
        }),
        "a skipped frame is detected"
    );
    // stateless decoding reads key frames only
    assert!(crate::frame::decode_frame_full(&k).is_ok());
    assert!(matches!(
        crate::frame::decode_frame_full(&d6),
        Err(FrameError::Base { .. })
    ));
    enc.reset();
    let k8 = enc.encode(&header(8), &p);
    assert_eq!(k8[96], 1, "after a reset the next frame is a key frame");
    assert!(dec.decode(&k8).is_ok());
}

#[test]
fn a_new_vertex_count_or_a_far_jump_makes_a_key_frame() {
    let mut enc = DeltaEncoder::new();
    enc.encode(&header(1), &sheet(10, 0.0, 0.1));
    assert_eq!(enc.encode(&header(2), &sheet(11, 0.0, 0.1))[96], 1);
    let far: Vec<[f64; 3]> = sheet(11, 0.0, 0.1)
        .iter()
        .map(|p| [p[0] + 1e9, p[1], p[2]])
        .collect();
    let f = enc.encode(&header(3), &far);
    assert_eq!(f[96], 1, "an index out of i32 starts a new grid");
    let mut dec = FrameDecoder::new();
    let d = dec.decode(&f).unwrap();
    assert!(max_dist(&far, &d.positions) < 1e9 * 1e-6);
    // non-finite positions do not panic
    let bad = vec![[f64::NAN, 0.0, 0.0], [f64::INFINITY, 1.0, 2.0]];
    let b = DeltaEncoder::new().encode(&header(4), &bad);
    let _ = FrameDecoder::new().decode(&b);
}

proptest! {
    /// Any sequence of poses, some vertices moving by random amounts, some
    /// still, decodes to within 1.47 grid steps, and 9.4e-5 of the pose's
    /// diagonal, of every pose, however long the run of changes.
    #[test]
    fn a_stream_of_changes_decodes_within_the_grid(
        start in prop::collection::vec(prop::array::uniform3(-10.0f64..10.0), 1..60),
        moves in prop::collection::vec(
            (prop::collection::vec(prop::array::uniform3(-0.5f64..0.5), 60), 0.0f64..1.0),
            1..12,
        ),
    ) {
        let mut enc = DeltaEncoder::new();
        let mut dec = FrameDecoder::new();
        let mut pose = start.clone();
        let mut revision = 1;
        let b = enc.encode(&header(revision), &pose);
        let f = dec.decode(&b).unwrap();
        let step = f64::from_le_bytes(b[112..120].try_into().unwrap());
        prop_assert!(max_dist(&pose, &f.positions) <= 0.87 * step + 1e-5);
        for (m, still) in moves {
            for (i, p) in pose.iter_mut().enumerate() {
                if (i as f64 / 60.0) >= still {
                    for k in 0..3 {
                        p[k] += m[i][k];
                    }
                }
            }
            revision += 1;
            let b = enc.encode(&header(revision), &pose);
            let f = dec.decode(&b).unwrap();
            prop_assert_eq!(f.header.revision, revision);
            // within 0.85 grid steps per axis, and the grid within 1.05
            // steps per 16384th of the pose's diagonal (plus the f32
            // rounding of coordinates up to ~30)
            let step = f64::from_le_bytes(b[112..120].try_into().unwrap());
            let d = max_dist(&pose, &f.positions);
            prop_assert!(d <= 1.4723 * step + 1e-5, "{} against step {}", d, step);
            prop_assert!(d <= 9.4e-5 * diagonal(&pose) + 1e-5);
        }
    }

    /// A damaged frame is a typed error, never a panic, and a decoder that
    /// failed on a damaged stream then wants a key frame.
    #[test]
    fn damaged_frames_are_errors(at in 96usize..400, byte in any::<u8>(), cut in 0usize..400) {
        let mut enc = DeltaEncoder::new();
        let p = sheet(12, 0.0, 0.1);
        let k = enc.encode(&header(1), &p).to_vec();
        let mut bad = k.clone();
        let at = at % bad.len();
        bad[at] ^= byte | 1;
        let _ = FrameDecoder::new().decode(&bad);
        let _ = FrameDecoder::new().decode(&k[..cut.min(k.len())]);
        let mut dec = FrameDecoder::new();
        dec.decode(&k).unwrap();
        let d = enc.encode(&header(2), &sheet(12, 0.1, 0.1)).to_vec();
        let mut bad = d.clone();
        let at = DELTA_STREAM_OFFSET + at % (bad.len() - DELTA_STREAM_OFFSET);
        bad[at] ^= byte | 1;
        if dec.decode(&bad).is_err() {
            let again = dec.decode(&d);
            prop_assert!(matches!(again, Err(FrameError::Base { .. })), "{:?}", again);
        }
    }
}
