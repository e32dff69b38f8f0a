//! A takeover inside PostgreSQL's reconnect grace (docs/architecture.md,
//! "Sessions: phases and ownership"): two `dend serve` instances on one
//! throw-away PostgreSQL with the default 10 s lease. Session S is posed on
//! A over WebSocket (its drags in the journal only), PostgreSQL is
//! restarted, and A is SIGKILLed at once, inside the grace in which the
//! liveness check cannot yet tell a dead owner from one reconnecting. B is
//! read and dragged throughout. Checked:
//! - every pose B serves holds the acknowledged drags and is the settled
//!   revived pose (flagged settled, within 0.02 of A's settled pose at
//!   every vertex), never an iterate of the revival's solve;
//! - every refusal (409 `session_owned_elsewhere`) names a retry hint no
//!   longer than the wait that followed it: the end of the grace, not the
//!   10 s the dead owner's lease had left;
//! - the drag sent to B is applied on the acknowledged ones.
//!
//! Needs PostgreSQL's server binaries: skipped (logged to `$DEND_SKIP_LOG`)
//! when they are missing, a failure under `CI=true`.

use std::time::{Duration, Instant};

use dend_client::ws::{ClientMsg, DeltaJson};
use dend_client::{Client, ClientError, ErrorCode, Pose, SessionParams};
use dend_testkit::server::{grid, grid_constraints};

use crate::failover_support::{free_port, postgres_prerequisite, Instance, Postgres};

const N: usize = 8;
const LEASE_TTL_MS: u64 = 10_000;

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_takeover_inside_the_reconnect_grace_serves_settled_poses_and_true_hints(
) -> Result<(), String> {
    if let Err(why) = postgres_prerequisite() {
        assert!(
            std::env::var("CI").map_or(true, |v| v != "true"),
            "{why}: CI installs it (.ci/run)"
        );
        dend_testkit::record_skip(&why);
        return Ok(());
    }
    let tmp = tempfile::tempdir().map_err(|e| e.to_string())?;
    let dir = tmp.path().to_owned();
    let pg = Postgres::start(&dir.join("pg"), free_port()?)?;
    let mut a = Instance::start(&dir, "dend1", &pg.url, LEASE_TTL_MS)?;
    let b = Instance::start(&dir, "dend2", &pg.url, LEASE_TTL_MS)?;
    let outcome = run(&pg, &mut a, &b).await;
    if outcome.is_err() {
        for id in ["dend1", "dend2"] {
            let log = std::fs::read_to_string(dir.join(format!("{id}.log"))).unwrap_or_default();
            let tail: Vec<&str> = log.lines().rev().take(15).collect();
            eprintln!(
                "--- {id} log tail:\n{}",
                tail.into_iter().rev().collect::<Vec<_>>().join("\n")
            );
        }
    }
    outcome
}

/// x offset of the handle row from rest.
fn offset(p: &Pose) -> f64 {
    p.positions[N * (N - 1)][0]
}

/// The largest distance between two poses' vertices.
fn distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

/// The retry hint of a `session_owned_elsewhere` message.
fn retry_hint(message: &str) -> Option<Duration> {
    let rest = message.split("retry in ").nth(1)?;
    Some(Duration::from_millis(rest.split(' ').next()?.parse().ok()?))
}

async fn run(pg: &Postgres, a: &mut Instance, b: &Instance) -> Result<(), String> {
    let e = |e: ClientError| e.to_string();
    let ca = Client::new(&a.base);
    let (p, t) = grid(N);
    let mesh = ca.upload_json(&p, &t).await.map_err(e)?;
    let s = ca
        .create_session(&mesh.id, SessionParams::default())
        .await
        .map_err(e)?;
    let sa = ca.session(&s.id, &s.token);
    sa.set_constraints(&grid_constraints(N)).await.map_err(e)?;
    sa.wait_ready(Duration::from_secs(30)).await.map_err(e)?;
    let mut ws = sa.connect().await.map_err(e)?;
    ws.send(&ClientMsg::Grab { handle: 0.into() })
        .await
        .map_err(e)?;
    for seq in 1..=10 {
        ws.drag(0, [0.15, 0.0, 0.0], None, seq).await.map_err(e)?;
        let _ = ws.frame_acking(seq, false).await.map_err(e)?;
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    let settled = loop {
        let p = sa.pose().await.map_err(e)?;
        if p.settled {
            break p;
        }
        if Instant::now() > deadline {
            return Err("A never settled".into());
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    };

    // the grace starts with PostgreSQL; A dies inside it
    pg.stop()?;
    pg.restart()?;
    let restarted = Instant::now();
    a.kill();
    let killed = restarted.elapsed();

    let sb = Client::new(&b.base).session(&s.id, &s.token);
    let end = Instant::now() + Duration::from_secs(15);
    let mut refusals: Vec<(Instant, Duration)> = vec![];
    let mut first_pose = None;
    let mut poses = 0;
    while Instant::now() < end {
        match sb.pose().await {
            Ok(p) => {
                let at = Instant::now();
                first_pose.get_or_insert(at);
                poses += 1;
                if (offset(&p) - 1.5).abs() > 1e-6 {
                    return Err(format!(
                        "a pose without the acknowledged drags: {}",
                        offset(&p)
                    ));
                }
                let off = distance(&p.positions, &settled.positions);
                if !p.settled || off > 0.02 {
                    return Err(format!(
                        "an iterate was served: settled {}, iteration {}, {off} from the settled pose",
                        p.settled, p.iteration
                    ));
                }
                if poses >= 20 {
                    break;
                }
            }
            Err(ClientError::Api {
                code: ErrorCode::SessionOwnedElsewhere,
                message,
                ..
            }) => {
                let hint = retry_hint(&message).ok_or(format!("no retry hint: {message}"))?;
                refusals.push((Instant::now(), hint));
            }
            // PostgreSQL coming back
            Err(ClientError::Api {
                code: ErrorCode::StoreUnavailable,
                ..
            }) => {}
            Err(other) => return Err(other.to_string()),
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let first_pose = first_pose.ok_or("B never served the session")?;
    for (at, hint) in &refusals {
        let waited = first_pose.saturating_duration_since(*at);
        if *hint > waited + Duration::from_millis(500) {
            return Err(format!(
                "a refusal said to retry in {hint:?}; B served the session {waited:?} later \
                 (A killed {killed:?} after PostgreSQL started)"
            ));
        }
    }
    let dragged = sb
        .drag(0, DeltaJson::new([0.25, 0.0, 0.0], None), None)
        .await
        .map_err(e)?;
    if (offset(&dragged) - 1.75).abs() > 1e-6 {
        return Err(format!("the drag on B: offset {}", offset(&dragged)));
    }
    Ok(())
}
