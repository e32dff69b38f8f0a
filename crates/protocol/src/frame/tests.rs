use super::*;
use proptest::prelude::*;

fn header(n: usize) -> FrameHeader {
    FrameHeader {
        revision: 7,
        ack_seq: 0x0102_0304_0506_0708,
        iteration: 9,
        converged: true,
        settled: false,
        objective: 12.5,
        vertex_count: n as u32,
        level: LEVEL_FULL,
    }
}

fn diagonal(b: [[f64; 3]; 2]) -> f64 {
    (0..3)
        .map(|k| (b[1][k] - b[0][k]).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn version_2_layout_is_fixed_and_round_trips() {
    let pose = [[1.0, -2.0, 3.5], [0.25, 0.0, -1e3]];
    let h = header(2);
    let bytes = FrameBody::from_pose(&pose).finish(&h);
    assert_eq!(bytes.len(), 40 + 24);
    assert_eq!(&bytes[0..4], b"DEND");
    assert_eq!(bytes[4], 2, "format version 2");
    assert_eq!(bytes[6], 1, "converged flag is bit 0 of the flags");
    assert_eq!(bytes[16], 0x08, "ack seq is little-endian at offset 16");
    assert_eq!(&bytes[32..40], &12.5f64.to_le_bytes());
    assert_eq!(&bytes[40..44], &1.0f32.to_le_bytes());
    let (h2, v) = decode_frame(&bytes).unwrap();
    assert_eq!(h2, h);
    assert_eq!(v, vec![[1.0, -2.0, 3.5], [0.25, 0.0, -1e3]]);
    let settled = FrameBody::from_pose(&pose).finish(&FrameHeader { settled: true, ..h });
    assert_eq!(settled[6], 3, "settled flag is bit 1");
    assert!(decode_frame(&settled).unwrap().0.settled);
    assert_eq!(
        decode_frame(&bytes[..48]),
        Err(FrameError::Length {
            got: 48,
            expected: 64
        })
    );
    assert_eq!(
        decode_frame(b"XEND00000000000000000000000000000000000"),
        Err(FrameError::Length {
            got: 39,
            expected: 40
        })
    );
    assert_eq!(
        decode_frame(b"XEND000000000000000000000000000000000000"),
        Err(FrameError::Magic)
    );
}

#[test]
fn version_3_layout_is_fixed() {
    let pose = [[1.0, -2.0, 3.5], [3.0, 0.0, -1.5]];
    let h = FrameHeader {
        level: LEVEL_COARSE,
        ..header(2)
    };
    let q = encode_frame_v3(&h, &pose, FrameEncoding::Q16);
    assert_eq!(q.len(), 96 + 2 * 6);
    assert_eq!(&q[0..4], b"DEND");
    assert_eq!(q[4], 3, "format version 3");
    assert_eq!(q[40], 1, "level at offset 40");
    assert_eq!(q[41], 1, "q16 is encoding 1");
    assert_eq!(&q[42..48], &[0; 6], "reserved bytes are zero");
    assert_eq!(&q[48..56], &1.0f64.to_le_bytes(), "box min x");
    assert_eq!(&q[72..80], &3.0f64.to_le_bytes(), "box max x");
    // the first vertex is the box's min along x and y, its max along z
    assert_eq!(&q[96..98], &0u16.to_le_bytes());
    assert_eq!(&q[98..100], &0u16.to_le_bytes());
    assert_eq!(&q[100..102], &65535u16.to_le_bytes());
    let d = decode_frame_full(&q).unwrap();
    assert_eq!(d.header, h);
    assert_eq!(d.version, 3);
    assert_eq!(d.encoding, FrameEncoding::Q16);
    assert_eq!(d.bbox, Some([[1.0, -2.0, -1.5], [3.0, 0.0, 3.5]]));
    assert_eq!(d.positions, vec![[1.0, -2.0, 3.5], [3.0, 0.0, -1.5]]);
    let f = encode_frame_v3(&h, &pose, FrameEncoding::F32);
    assert_eq!(f.len(), 96 + 2 * 12);
    assert_eq!(f[41], 0, "f32 is encoding 0");
    assert_eq!(decode_frame(&f).unwrap().1, d.positions);
}

#[test]
fn q16_is_half_the_bytes_of_f32() {
    let pose: Vec<[f64; 3]> = (0..1000).map(|i| [i as f64, 0.5, -(i as f64)]).collect();
    let h = header(pose.len());
    let v2 = FrameBody::from_pose(&pose).finish(&h).len();
    let f32_v3 = encode_frame_v3(&h, &pose, FrameEncoding::F32).len();
    let q16 = encode_frame_v3(&h, &pose, FrameEncoding::Q16).len();
    assert_eq!(v2, 40 + 12 * 1000);
    assert_eq!(f32_v3, 96 + 12 * 1000);
    assert_eq!(q16, 96 + 6 * 1000);
    assert!((q16 as f64) < 0.51 * v2 as f64, "{q16} vs {v2}");
}

#[test]
fn a_flat_axis_decodes_exactly() {
    // every vertex at z = 2: the box is flat along z, q is 0, no division by zero
    let pose = [[0.0, 0.0, 2.0], [1.0, 1.0, 2.0], [0.5, 0.25, 2.0]];
    let q = encode_frame_v3(&header(3), &pose, FrameEncoding::Q16);
    let (_, v) = decode_frame(&q).unwrap();
    assert!(v.iter().all(|p| p[2] == 2.0));
    let empty = encode_frame_v3::<f64>(&header(0), &[], FrameEncoding::Q16);
    assert!(decode_frame(&empty).unwrap().1.is_empty());
}

#[test]
fn malformed_version_3_frames_get_typed_errors() {
    let pose = [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]];
    let good = encode_frame_v3(&header(2), &pose, FrameEncoding::Q16).to_vec();
    let mut b = good.clone();
    b[4] = 4;
    assert_eq!(decode_frame(&b), Err(FrameError::Version(4)));
    let mut b = good.clone();
    b[41] = 3;
    assert_eq!(decode_frame(&b), Err(FrameError::Encoding(3)));
    let mut b = good.clone();
    b[40] = 2;
    assert_eq!(decode_frame(&b), Err(FrameError::Level(2)));
    let mut b = good.clone();
    b[48..56].copy_from_slice(&f64::NAN.to_le_bytes());
    assert_eq!(decode_frame(&b), Err(FrameError::Box));
    let mut b = good.clone();
    b[48..56].copy_from_slice(&5.0f64.to_le_bytes());
    assert_eq!(decode_frame(&b), Err(FrameError::Box), "min above max");
    assert_eq!(
        decode_frame(&good[..60]),
        Err(FrameError::Length {
            got: 60,
            expected: 96
        })
    );
    assert_eq!(
        decode_frame(&good[..good.len() - 1]),
        Err(FrameError::Length {
            got: good.len() - 1,
            expected: good.len()
        })
    );
    let mut b = good.clone();
    b[28..32].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(matches!(decode_frame(&b), Err(FrameError::Length { .. })));
}

#[test]
fn reencoding_a_version_2_frame_keeps_its_header() {
    let pose = [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]];
    let h = header(2);
    let v2 = FrameBody::from_pose(&pose).finish(&h);
    let h3 = FrameHeader {
        level: LEVEL_COARSE,
        ..h
    };
    let v3 = reencode_v2(&v2, &h3, FrameEncoding::F32).unwrap();
    assert_eq!(
        decode_frame(&v3).unwrap(),
        (h3, decode_frame(&v2).unwrap().1)
    );
    assert_eq!(
        reencode_v2(&v2[..50], &h3, FrameEncoding::Q16),
        Err(FrameError::Length {
            got: 50,
            expected: 64
        })
    );
}

fn pose_strategy() -> impl Strategy<Value = Vec<[f64; 3]>> {
    // a random scale and offset, as meshes come in any units
    (
        prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 1..200),
        -3.0f64..3.0,
        prop::array::uniform3(-1e3f64..1e3),
    )
        .prop_map(|(p, log_scale, off)| {
            let s = 10f64.powf(log_scale);
            p.into_iter()
                .map(|v| std::array::from_fn(|k| v[k] * s + off[k]))
                .collect()
        })
}

proptest! {
    /// Every decoded vertex is within 1e-4 of the box diagonal of its pose
    /// (the quantisation bound is 1/131070 of each axis' extent, plus the
    /// f32 rounding of the decoded value).
    #[test]
    fn q16_round_trip_error_is_below_1e_4_of_the_diagonal(pose in pose_strategy()) {
        let bytes = encode_frame_v3(&header(pose.len()), &pose, FrameEncoding::Q16);
        let d = decode_frame_full(&bytes).unwrap();
        let diag = diagonal(bounding_box(&pose));
        let mut worst = 0.0f64;
        for (a, b) in pose.iter().zip(&d.positions) {
            let e = (0..3).map(|k| (a[k] - f64::from(b[k])).powi(2)).sum::<f64>().sqrt();
            worst = worst.max(e);
        }
        // f32 of the decoded value: its relative rounding against the offset
        let f32_floor = pose.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs())) * 1.2e-7;
        prop_assert!(worst <= 1e-4 * diag + f32_floor, "error {worst} of diagonal {diag}");
        prop_assert_eq!(d.positions.len(), pose.len());
    }

    /// Arbitrary bytes decode or give a typed error, never a panic; and a
    /// frame with any single byte changed does the same.
    #[test]
    fn arbitrary_bytes_give_typed_errors(
        prefix in prop::sample::select(vec![&b"DEND\x02\x00"[..], &b"DEND\x03\x00"[..], &b""[..]]),
        rest in prop::collection::vec(any::<u8>(), 0..300),
    ) {
        let bytes = [prefix, &rest[..]].concat();
        if let Ok(d) = decode_frame_full(&bytes) {
            prop_assert_eq!(d.positions.len(), d.header.vertex_count as usize);
        }
    }

    #[test]
    fn a_frame_with_a_byte_changed_never_panics(
        pose in pose_strategy(), at in any::<prop::sample::Index>(), v in any::<u8>(),
    ) {
        let mut b = encode_frame_v3(&header(pose.len()), &pose, FrameEncoding::Q16).to_vec();
        let i = at.index(b.len());
        b[i] = v;
        if let Ok(d) = decode_frame_full(&b) {
            prop_assert_eq!(d.positions.len(), d.header.vertex_count as usize);
        }
    }
}
