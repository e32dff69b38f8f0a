//! Crash safety of `dend serve --data-dir`: a real server process, real
//! WebSocket clients dragging, `kill -9` at random moments, restart.
//!
//! Per run: start the server on port 0 (the printed URL), reconnect every
//! session with its id and token (the server re-opens it from the store),
//! wait for `ready`, drag (1–3 deltas in flight), `kill -9` after a random
//! delay (every fifth run right after start-up, while sessions re-open).
//! Then, with the server dead, open the SQLite store directly and check:
//! integrity, every session present, the recovered sequence number covers
//! every drag a frame acknowledged (lost = 0), and the recovered handle
//! target equals the library's composition (`RigidTransform::then`) of
//! exactly the deltas sent up to that sequence number. A last restart
//! checks the sessions come back `ready` with that `ack_seq` and a finite,
//! non-rest pose.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

use dend::deform::{ConstraintsSpec, RigidTransform};
use dend::mesh::Mesh;
use dend_client::ws::{ServerMsg, SessionState};
use dend_client::{Client, SessionParams, WsClient, WsEvent};
use dend_server::session::Recovered;
use dend_server::store::{SessionLog, SqliteStore};
use nalgebra::{Quaternion, UnitQuaternion};
use parking_lot::Mutex;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const RUNS: usize = 22;
const SESSIONS: usize = 3;
const N: usize = 10;

type Res<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

struct Server {
    child: Child,
    base: String,
}

fn start(dir: &std::path::Path) -> Res<Server> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_dend"))
        .args([
            "serve",
            "--addr",
            "127.0.0.1:0",
            "--ws-max-messages-per-sec",
            "100000",
            "--data-dir",
        ])
        .arg(dir)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()?;
    let stdout = child.stdout.take().ok_or("no stdout")?;
    let mut lines = BufReader::new(stdout).lines();
    let base = loop {
        let line = lines
            .next()
            .ok_or("server exited before printing its URL")??;
        if let Some(url) = line.strip_prefix("listening on ") {
            break url.trim().to_owned();
        }
    };
    // keep draining stdout so the server never blocks on a full pipe
    drop(std::thread::spawn(move || for _ in lines.by_ref() {}));
    Ok(Server { child, base })
}

fn spec() -> dend_client::ConstraintsSpec {
    use dend_client::{HandleSpec, VertexSet};
    let hi = N as f64 - 1.5;
    dend_client::ConstraintsSpec::new(
        VertexSet::bbox([-1.0, -1.0, -1.0], [0.5, 100.0, 1.0]),
        vec![HandleSpec::named(
            "right",
            VertexSet::bbox([hi, -1.0, -1.0], [100.0, 100.0, 1.0]),
        )],
    )
}

/// One sent delta: (seq, translation, quaternion `[x, y, z, w]`).
type Sent = (u64, [f64; 3], [f64; 4]);

struct Sess {
    id: String,
    token: String,
    sent: Arc<Mutex<Vec<Sent>>>,
    acked: Arc<Mutex<u64>>,
    next_seq: u64,
}

fn compose(initial: &RigidTransform, sent: &[Sent], upto: u64) -> RigidTransform {
    let mut t = *initial;
    for (_, tr, q) in sent.iter().filter(|s| s.0 <= upto) {
        let rot = UnitQuaternion::from_quaternion(Quaternion::new(q[3], q[0], q[1], q[2]));
        t = t.then(rot, *tr);
    }
    t
}

fn close(a: &RigidTransform, b: &RigidTransform) -> bool {
    let d = (a.rotation.coords - b.rotation.coords).norm()
        + (0..3)
            .map(|k| (a.translation[k] - b.translation[k]).abs() + (a.pivot[k] - b.pivot[k]).abs())
            .sum::<f64>();
    d < 1e-9
}

/// Reads until the session is ready (a `state` saying so, or `ready`).
async fn until_ready(ws: &mut WsClient) -> Res<()> {
    loop {
        match ws.next().await? {
            WsEvent::Event(ServerMsg::Ready { .. }) => return Ok(()),
            WsEvent::Event(ServerMsg::State { session, .. })
                if session.state == SessionState::Ready =>
            {
                return Ok(())
            }
            WsEvent::Event(e @ ServerMsg::Error { .. }) => {
                return Err(format!("error event {e:?}").into())
            }
            WsEvent::Closed(c) => return Err(format!("closed {c:?} before ready").into()),
            _ => {}
        }
    }
}

/// Drags until the connection dies; every acknowledged seq goes to `acked`.
async fn drag_loop(
    mut ws: WsClient,
    sent: Arc<Mutex<Vec<Sent>>>,
    acked: Arc<Mutex<u64>>,
    mut seq: u64,
    seed: u64,
) -> Res<()> {
    let mut rng = StdRng::seed_from_u64(seed);
    loop {
        let burst = rng.random_range(1..=3);
        for _ in 0..burst {
            seq += 1;
            // dyadic components: exact in JSON both ways
            let tr = [
                rng.random_range(-8..=8) as f64 / 1024.0,
                rng.random_range(1..=8) as f64 / 1024.0,
                0.0,
            ];
            let q = [0.0, 0.0, rng.random_range(-4..=4) as f64 / 512.0, 1.0];
            sent.lock().push((seq, tr, q));
            ws.drag(0, tr, Some(q), seq).await?;
        }
        loop {
            match ws.next().await? {
                WsEvent::Frame(h, _) => {
                    let mut a = acked.lock();
                    *a = (*a).max(h.ack_seq);
                    if h.ack_seq >= seq {
                        break;
                    }
                }
                WsEvent::Event(e @ ServerMsg::Error { .. }) => {
                    return Err(format!("error event {e:?}").into())
                }
                WsEvent::Closed(c) => return Err(format!("closed {c:?}").into()),
                WsEvent::Event(_) => {}
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kill_9_loses_no_acknowledged_drag() -> Res<()> {
    let dir = tempfile::tempdir()?;
    let (positions, triangles) = dend_testkit::server::grid(N);
    let mesh = Mesh::new(positions.clone(), triangles.clone())?;
    let spec_json = spec();
    let initial = serde_json::from_value::<ConstraintsSpec>(serde_json::to_value(&spec_json)?)?
        .resolve(&mesh)?
        .handles[0]
        .target;

    // set-up: mesh, sessions, constraints
    let mut server = start(dir.path())?;
    let client = Client::new(&server.base);
    let info = client.upload_json(&positions, &triangles).await?;
    let mut sessions = vec![];
    for _ in 0..SESSIONS {
        let s = client
            .create_session(
                &info.id,
                SessionParams {
                    max_iters: Some(8),
                    ..SessionParams::default()
                },
            )
            .await?;
        s.set_constraints(&spec_json).await?;
        s.wait_ready(Duration::from_secs(30)).await?;
        sessions.push(Sess {
            id: s.id.clone(),
            token: s.token.clone(),
            sent: Arc::default(),
            acked: Arc::default(),
            next_seq: 0,
        });
    }

    let mut rng = StdRng::seed_from_u64(0x5eed);
    let (mut acked_total, mut lost, mut journaled_total) = (0u64, 0u64, 0usize);
    for run in 0..RUNS {
        if run > 0 {
            server = start(dir.path())?;
        }
        let client = Client::new(&server.base);
        let mut tasks = vec![];
        let early_kill = run % 5 == 4;
        if !early_kill {
            for (k, s) in sessions.iter().enumerate() {
                let mut ws = client.session(&s.id, &s.token).connect().await?;
                tokio::time::timeout(Duration::from_secs(30), until_ready(&mut ws)).await??;
                let seed = (run * SESSIONS + k) as u64;
                tasks.push(tokio::spawn(drag_loop(
                    ws,
                    s.sent.clone(),
                    s.acked.clone(),
                    s.next_seq,
                    seed,
                )));
            }
            tokio::time::sleep(Duration::from_millis(rng.random_range(20..400))).await;
        } else {
            // kill while the sessions are being re-opened
            for s in &sessions {
                let c = client.session(&s.id, &s.token);
                tasks.push(tokio::spawn(async move {
                    c.connect()
                        .await
                        .map(drop)
                        .map_err(|e| -> Box<dyn std::error::Error + Send + Sync> { Box::new(e) })
                }));
            }
            tokio::time::sleep(Duration::from_millis(rng.random_range(0..30))).await;
        }
        server.child.kill()?; // SIGKILL
        let _ = server.child.wait()?;
        for t in tasks {
            // every client ends with a connection error: the server is dead
            let _ = t.await?;
        }

        // the server is dead: inspect what it left behind
        let store = SqliteStore::open(dir.path())?;
        store.integrity_check()?;
        let records = store.list_sessions()?;
        assert_eq!(
            records.len(),
            SESSIONS,
            "run {run}: every session is stored"
        );
        for s in &mut sessions {
            let record = store.get_session(&s.id)?.ok_or("session missing")?;
            let stored_spec = record.constraints.ok_or("constraints missing")?;
            let journal = store.journal(&s.id)?;
            let checkpoint = store.get_checkpoint(&s.id)?;
            journaled_total += journal.len();
            let rec = Recovered::new(checkpoint, journal);
            let mut constraints =
                serde_json::from_value::<ConstraintsSpec>(stored_spec)?.resolve(&mesh)?;
            rec.apply(&mut constraints)?;
            let acked = *s.acked.lock();
            let mut sent = s.sent.lock();
            let max_sent = sent.last().map_or(0, |x| x.0);
            let new_acked = sent
                .iter()
                .filter(|x| x.0 > s.next_seq && x.0 <= acked)
                .count() as u64;
            acked_total += new_acked;
            lost += sent
                .iter()
                .filter(|x| x.0 <= acked && x.0 > rec.ack_seq)
                .count() as u64;
            assert!(
                rec.ack_seq >= acked,
                "run {run}: acknowledged seq {acked} but recovered only {}",
                rec.ack_seq
            );
            assert!(
                rec.ack_seq <= max_sent.max(s.next_seq),
                "run {run}: recovered seq {} never sent",
                rec.ack_seq
            );
            let expected = compose(&initial, &sent, rec.ack_seq);
            assert!(
                close(&constraints.handles[0].target, &expected),
                "run {run}: recovered target {:?} != composition up to seq {}: {:?}",
                constraints.handles[0].target,
                rec.ack_seq,
                expected
            );
            // what the server did not journal was never acknowledged: forget it
            sent.retain(|x| x.0 <= rec.ack_seq);
            s.next_seq = max_sent.max(s.next_seq);
            *s.acked.lock() = rec.ack_seq;
        }
    }
    println!(
        "crash test: {RUNS} kill -9 runs, {SESSIONS} sessions, {acked_total} acknowledged drags, \
         {journaled_total} journal entries found after kills, lost {lost}"
    );
    assert_eq!(lost, 0);
    assert!(
        acked_total > 0,
        "the test must acknowledge drags to mean anything"
    );

    // a last restart: everything comes back ready with the recovered seq
    let mut server = start(dir.path())?;
    let client = Client::new(&server.base);
    for s in &sessions {
        let sc = client.session(&s.id, &s.token);
        let mut ws = sc.connect().await?;
        tokio::time::timeout(Duration::from_secs(30), until_ready(&mut ws)).await??;
        sc.wait_ready(Duration::from_secs(30)).await?;
        let acked = *s.acked.lock();
        let seq = acked + 1;
        ws.drag(0, [0.0, 1.0 / 1024.0, 0.0], None, seq).await?;
        let (h, pose) =
            tokio::time::timeout(Duration::from_secs(30), ws.frame_acking(seq, false)).await??;
        assert_eq!(h.ack_seq, seq);
        assert_eq!(pose.len(), N * N);
        assert!(pose.iter().flatten().all(|x| x.is_finite()));
        let moved = pose
            .iter()
            .zip(&positions)
            .map(|(p, q)| (p[1] as f64 - q[1]).abs())
            .fold(0.0, f64::max);
        assert!(
            moved > 1e-3,
            "the recovered pose carries the drags (max move {moved})"
        );
    }
    server.child.kill()?;
    let _ = server.child.wait()?;
    Ok(())
}
