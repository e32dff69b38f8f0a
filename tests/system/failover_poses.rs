//! Named poses survive a failover (PostgreSQL; docs/deployment.md): two `dend serve`
//! instances on one throw-away PostgreSQL. Session S is created, posed and
//! given two named poses (one renamed) through instance A, then A is
//! SIGKILLed (no shutdown, no lease release). Through instance B, once it
//! has taken S over: the list holds the same names in the same order, each
//! named pose has the same positions bit for bit, and restoring one makes
//! it the current pose there.
//!
//! Needs PostgreSQL's server binaries: skipped (logged to `$DEND_SKIP_LOG`)
//! when they are missing, a failure under `CI=true`.

use std::time::{Duration, Instant};

use dend_client::ws::DeltaJson;
use dend_client::{Client, ClientError, RenamePose, SavePose, SessionClient, SessionParams};
use dend_testkit::server::{grid, grid_constraints};
use serde_json::Value;

use crate::failover_support::{free_port, postgres_prerequisite, Instance, Postgres};

const N: usize = 8; // grid side: the handle `top` is the top row
const LEASE_TTL_MS: u64 = 2000;

/// (status, JSON body) of a session route, `tail` after `/v1/sessions/{id}`.
async fn call(
    s: &SessionClient,
    base: &str,
    method: &str,
    tail: &str,
    body: Option<Value>,
) -> Result<(u16, Value), String> {
    let mut rq = reqwest::Client::new()
        .request(
            method
                .parse::<reqwest::Method>()
                .map_err(|e| e.to_string())?,
            format!("{base}/v1/sessions/{}{tail}", s.id),
        )
        .bearer_auth(&s.token);
    if let Some(b) = body {
        rq = rq.json(&b);
    }
    let r = rq.send().await.map_err(|e| e.to_string())?;
    let status = r.status().as_u16();
    let text = r.text().await.map_err(|e| e.to_string())?;
    Ok((status, serde_json::from_str(&text).unwrap_or(Value::Null)))
}

/// [`call`] until it answers something other than 409
/// `session_owned_elsewhere` (the dead owner's lease not yet taken over).
async fn call_after_takeover(
    s: &SessionClient,
    base: &str,
    method: &str,
    tail: &str,
) -> Result<(u16, Value), String> {
    let end = Instant::now() + Duration::from_secs(60);
    loop {
        let (st, v) = call(s, base, method, tail, None).await?;
        if !(st == 409 && v["code"] == "session_owned_elsewhere") {
            return Ok((st, v));
        }
        if Instant::now() > end {
            return Err(format!(
                "{method} {tail}: still owned elsewhere after 60 s: {v}"
            ));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

fn positions(v: &Value) -> Result<Vec<[f64; 3]>, String> {
    serde_json::from_value(v["positions"].clone()).map_err(|e| format!("positions of {v}: {e}"))
}

fn names(v: &Value) -> Vec<String> {
    v["poses"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|p| p["name"].as_str().map(str::to_owned))
                .collect()
        })
        .unwrap_or_default()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn named_poses_survive_a_failover_with_postgres() -> Result<(), String> {
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
    let outcome = run(&mut a, &b).await;
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

async fn run(a: &mut Instance, b: &Instance) -> Result<(), String> {
    let e = |e: ClientError| e.to_string();
    // S lives on A: created, posed and given its named poses there
    let api = Client::new(&a.base);
    let (p, t) = grid(N);
    let mesh = api.upload_json(&p, &t).await.map_err(e)?;
    let s = api
        .create_session(&mesh.id, SessionParams::default())
        .await
        .map_err(e)?;
    s.set_constraints(&grid_constraints(N)).await.map_err(e)?;
    s.wait_ready(Duration::from_secs(60)).await.map_err(e)?;
    let mut saved = vec![];
    for (name, dz) in [("low", 0.5), ("high", 2.0)] {
        let delta = DeltaJson::translate([0.0, 0.0, dz]);
        s.drag("top", delta, Some(100)).await.map_err(e)?;
        let save = SavePose {
            name: name.to_owned(),
            replace: false,
        };
        let (st, v) = call(&s, &a.base, "POST", "/poses", Some(json_of(save))).await?;
        assert_eq!(st, 201, "save {name} on A: {v}");
        let (st, v) = call(&s, &a.base, "GET", &format!("/poses/{name}"), None).await?;
        assert_eq!(st, 200, "read {name} on A: {v}");
        let got = positions(&v)?;
        assert_eq!(
            got,
            s.pose().await.map_err(e)?.positions,
            "{name}: the settled pose"
        );
        saved.push(got);
    }
    assert!(
        saved[0]
            .iter()
            .zip(&saved[1])
            .any(|(x, y)| (x[2] - y[2]).abs() > 1.0),
        "the two poses differ"
    );
    let (st, v) = call(
        &s,
        &a.base,
        "PATCH",
        "/poses/low",
        Some(json_of(RenamePose {
            name: "lower".into(),
        })),
    )
    .await?;
    assert_eq!(st, 200, "rename on A: {v}");
    let (_, on_a) = call(&s, &a.base, "GET", "/poses", None).await?;
    assert_eq!(names(&on_a), ["lower", "high"]);

    // acknowledged, then A is killed without warning
    let killed_at = Instant::now();
    a.kill();

    // B takes S over (once A's lease expires, or at once when it sees A's
    // liveness connection gone) and serves the poses from PostgreSQL
    let on_b = Client::new(&b.base).session(&s.id, &s.token);
    let (st, v) = call_after_takeover(&on_b, &b.base, "GET", "/poses").await?;
    assert_eq!(st, 200, "list on B: {v}");
    eprintln!(
        "named poses listed by B {} ms after the SIGKILL of A",
        killed_at.elapsed().as_millis()
    );
    assert_eq!(
        names(&v),
        ["lower", "high"],
        "the names and their order on B"
    );
    for (name, want) in ["lower", "high"].iter().zip(&saved) {
        let (st, got) =
            call_after_takeover(&on_b, &b.base, "GET", &format!("/poses/{name}")).await?;
        assert_eq!(st, 200, "read {name} on B: {got}");
        assert_eq!(&positions(&got)?, want, "{name} bit for bit on B");
    }
    on_b.wait_ready(Duration::from_secs(60)).await.map_err(e)?;
    let (st, back) = call_after_takeover(&on_b, &b.base, "POST", "/poses/lower/restore").await?;
    assert_eq!(st, 200, "restore on B: {back}");
    assert_eq!(positions(&back)?, saved[0], "the restored pose");
    assert_eq!(
        on_b.pose().await.map_err(e)?.positions,
        saved[0],
        "the current pose on B after the restore"
    );
    Ok(())
}

/// A typed body as its JSON.
fn json_of(v: impl serde::Serialize) -> serde_json::Value {
    serde_json::to_value(v).expect("a body")
}
