//! Path independence of the drag loop, end to end over a real socket
//! (docs/design.md): a generated limb-like creature dragged to one final target
//! in 1, 10 and 40 drags, each drag answered by a frame (one iteration),
//! then the settle. The settled poses must agree within 1e-3 of the
//! diagonal and their objectives within 1 % of the one-drag solve's.
//!
//! The sessions ask for `tol` 1e-5: at the default tolerance (1e-3 mean
//! edge lengths) the settled poses are 1–5e-3 of the diagonal apart
//! although their objectives agree to 3e-5 (the valley along which the
//! characters' energy is nearly flat; `examples/drag_sim.rs --tol`), so
//! the pose agreement is a property of the minimum, reached at a tighter
//! tolerance.

use std::time::Duration;

use dend::mesh::gen::{generate, Shape, ShapeSpec};
use dend::mesh::Mesh;
use dend_client::ws::{ServerMsg, StreamOptions};
use dend_client::{
    Client, ConstraintsSpec, FrameEncoding, HandleSpec, SessionParams, VertexSet, WsFull,
};
use dend_server::Config;
use dend_testkit::server::start;
use nalgebra::{UnitQuaternion, Vector3};

type R<T = ()> = Result<T, Box<dyn std::error::Error>>;

/// The creature at `levels` levels (3: about 9,200 vertices, with a
/// coarse level; 4: with a preview level too).
fn creature(levels: u32) -> Mesh {
    let mut s = ShapeSpec::default_for(Shape::Creature);
    s.params.nu = Some(levels);
    generate(&s).expect("creature")
}

/// The load test's edit: the lowest 10 % along the longest axis fixed, the
/// highest 10 % the handle; (constraints JSON, axis, extent).
fn edit(mesh: &Mesh) -> (ConstraintsSpec, usize, f64) {
    let (lo, hi) = mesh.bounding_box();
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0);
    let extent = hi[axis] - lo[axis];
    let at = |v: usize| mesh.positions()[v][axis];
    let n = mesh.num_vertices();
    let fixed: Vec<usize> = (0..n)
        .filter(|&v| at(v) < lo[axis] + 0.1 * extent)
        .collect();
    let handle: Vec<usize> = (0..n)
        .filter(|&v| at(v) > hi[axis] - 0.1 * extent)
        .collect();
    let c = ConstraintsSpec::new(
        VertexSet::indices(fixed),
        vec![HandleSpec::named("h", VertexSet::indices(handle))],
    );
    (c, axis, extent)
}

/// The handle's translation after a fraction `s` of the path: 0.3 of the
/// extent across the long axis, bowed out and back along an arc.
fn translation_at(s: f64, axis: usize, extent: f64) -> [f64; 3] {
    let mut t = [0.0; 3];
    t[(axis + 1) % 3] = 0.3 * extent * s;
    t[(axis + 2) % 3] = 0.15 * extent * (std::f64::consts::PI * s).sin();
    t
}

/// What a settled session ended with.
struct Settled {
    pose: Vec<[f64; 3]>,
    objective: f64,
    /// Frames of each level (full, coarse preview) before the settled one.
    levels: [usize; 2],
}

/// A session dragged to the final target (translation along the arc,
/// turning 60° about the long axis) in `drags` drags, each waited for,
/// then settled.
async fn drag_in(base: &str, mesh: &Mesh, drags: u64) -> R<Settled> {
    let c = Client::new(base);
    let uploaded = c.upload_json(mesh.positions(), mesh.triangles()).await?;
    let s = c
        // (tol 100× the default's: the valley is flat, and a closed-loop
        // gesture gets one iteration per drag, the refinements between
        // them stopped by the next drag; 12 drags without previews then
        // settled in over 100 iterations, 61 when each drag waited for the
        // refinement that had started)
        .create_session(
            &uploaded.id,
            SessionParams {
                tol: Some(1e-5),
                max_iters: Some(300),
                ..SessionParams::default()
            },
        )
        .await?;
    let (constraints, axis, extent) = edit(mesh);
    s.set_constraints(&constraints).await?;
    s.wait_ready(Duration::from_secs(120)).await?;
    let mut ws = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::F32))
        .await?;
    let mut a = Vector3::zeros();
    a[axis] = 60f64.to_radians() / drags as f64;
    let q = UnitQuaternion::from_scaled_axis(a);
    let q = [q.i, q.j, q.k, q.w];
    let mut levels = [0; 2];
    for k in 1..=drags {
        let (t0, t1) = (
            translation_at((k - 1) as f64 / drags as f64, axis, extent),
            translation_at(k as f64 / drags as f64, axis, extent),
        );
        let dt = [t1[0] - t0[0], t1[1] - t0[1], t1[2] - t0[2]];
        ws.drag(0, dt, Some(q), k).await?;
        if k < drags {
            // the frame that answers this drag comes first
            let (h, _) = ws.frame_acking(k, false).await?;
            levels[usize::from(h.level)] += 1;
        }
    }
    let objective = loop {
        match ws.next_full().await? {
            WsFull::Frame(f) if f.header.ack_seq >= drags && f.header.settled => {
                assert!(
                    f.header.converged,
                    "{drags} drags: settled at iteration {} without converging",
                    f.header.iteration
                );
                assert_eq!(
                    f.header.level,
                    dend_protocol::LEVEL_FULL,
                    "a settled preview"
                );
                break f.header.objective;
            }
            WsFull::Frame(f) => levels[usize::from(f.header.level)] += 1,
            WsFull::Event(e @ ServerMsg::Error { .. }) => return Err(format!("{e:?}").into()),
            WsFull::Closed(c) => return Err(format!("closed {c:?}").into()),
            _ => {}
        }
    };
    let pose = s.pose().await?.positions;
    Ok(Settled {
        pose,
        objective,
        levels,
    })
}

fn max_distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_creature_dragged_in_1_10_or_40_drags_settles_to_the_same_pose() -> R {
    let mesh = creature(3);
    let diag = mesh.diagonal();
    let (base, _state) = start(Config {
        ws_max_messages_per_sec: 100_000,
        ..Config::default()
    })
    .await;
    let one = drag_in(&base, &mesh, 1).await?;
    for drags in [10, 40] {
        let many = drag_in(&base, &mesh, drags).await?;
        let gap = max_distance(&many.pose, &one.pose) / diag;
        let ratio = many.objective / one.objective;
        eprintln!("{drags} drags: pose gap {gap:.2e} of the diagonal, objective ratio {ratio:.6}");
        assert!(
            gap <= 1e-3,
            "{drags} drags settled {gap:.2e} of the diagonal from the one-drag pose"
        );
        assert!(
            ratio <= 1.01,
            "{drags} drags settled at {ratio:.4} × the one-drag objective"
        );
    }
    Ok(())
}

/// Coarse previews (`preview_above_ms` 0: every drag of a gesture is
/// answered by one) on a creature with a preview level: the drag's frames
/// show level 1, the settled frame is the full mesh's, converged, and it
/// settles where a session without previews does.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn previews_answer_the_drags_and_the_full_mesh_settles_where_it_would_without() -> R {
    let mesh = creature(4);
    assert!(mesh.num_vertices() >= dend::deform::PREVIEW_MIN_VERTICES);
    let diag = mesh.diagonal();
    let mut settled = vec![];
    for preview_above_ms in [0.0, -1.0] {
        let (base, _state) = start(Config {
            ws_max_messages_per_sec: 100_000,
            preview_above_ms,
            ..Config::default()
        })
        .await;
        settled.push(drag_in(&base, &mesh, 12).await?);
    }
    let [with, without] = &settled[..] else {
        unreachable!()
    };
    eprintln!(
        "frames with previews {:?}, without {:?}",
        with.levels, without.levels
    );
    assert!(
        with.levels[1] >= 6,
        "previews answered {} of 11 drags",
        with.levels[1]
    );
    assert_eq!(without.levels[1], 0, "a preview while they were off");
    let gap = max_distance(&with.pose, &without.pose) / diag;
    let ratio = with.objective / without.objective;
    eprintln!("with previews: pose gap {gap:.2e} of the diagonal, objective ratio {ratio:.6}");
    assert!(
        gap <= 1e-3,
        "settled {gap:.2e} of the diagonal from the pose without previews"
    );
    assert!(
        ratio <= 1.01,
        "settled at {ratio:.4} × the objective without previews"
    );
    Ok(())
}
