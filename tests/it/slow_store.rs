//! A store made slow on purpose for one session does not delay another
//! session's frames: the session actor's store writes (checkpoint,
//! constraints) leave the async worker (`block_in_place`) while they block.

use std::sync::Arc;
use std::time::{Duration, Instant};

use dend_client::ws::{DeltaJson, ServerMsg};
use dend_client::{Client, ClientError, MeshJson, Pose, SessionParams, WsClient, WsEvent};
use dend_protocol::FrameHeader;
use dend_server::store::{with_faults, MemoryStore, Store};
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start_with_store};
use parking_lot::Mutex;

/// How a memory store is made slow: the constraint and checkpoint writes
/// of one session sleep `delay` first, and `mesh_count` takes
/// `count_delay` (a slow store widens upload races).
struct Slowness {
    slow: Mutex<Option<String>>,
    delay: Duration,
    count_delay: Duration,
}

/// A memory store slowed down as `slowness` says.
fn slow_store(slowness: &Arc<Slowness>) -> Arc<dyn Store> {
    let s = slowness.clone();
    Arc::new(with_faults(Arc::new(MemoryStore::new()), move |call| {
        match call.op {
            "mesh_count" => std::thread::sleep(s.count_delay),
            "set_constraints" | "checkpoint"
                if s.slow
                    .lock()
                    .as_deref()
                    .is_some_and(|id| call.id == Some(id)) =>
            {
                std::thread::sleep(s.delay);
            }
            _ => {}
        }
        Ok(())
    }))
}

/// One async worker thread, so that a write blocking it would stop every
/// other task: session A's checkpoints take 1.5 s each while session B is
/// dragged over WebSocket; B's frames keep coming.
#[tokio::test(flavor = "multi_thread", worker_threads = 1)]
async fn a_slow_store_for_one_session_does_not_stall_another() -> Result<(), ClientError> {
    let store = Arc::new(Slowness {
        slow: Mutex::new(None),
        delay: Duration::from_millis(1500),
        count_delay: Duration::ZERO,
    });
    let (base, _state) = start_with_store(Config::default(), slow_store(&store)).await;

    let c = Client::new(&base);
    let (p, t) = grid(8);
    let mesh = c.upload_json(&p, &t).await?;
    let a = c.create_session(&mesh.id, SessionParams::default()).await?;
    let b = c.create_session(&mesh.id, SessionParams::default()).await?;
    for s in [&a, &b] {
        s.set_constraints(&grid_constraints(8)).await?;
        s.wait_ready(Duration::from_secs(60)).await?;
    }
    let mut ws = b.connect().await?;
    let _ = ws.frame_acking(0, true).await?;
    *store.slow.lock() = Some(a.id.clone());

    // A: drags answered after a settle, each followed by a slow checkpoint
    let slow = tokio::spawn(async move {
        for k in 0..3 {
            let d = DeltaJson::translate([0.0, 0.0, 0.1 * (k + 1) as f64]);
            a.drag(0, d, Some(200)).await?;
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Ok::<_, ClientError>(())
    });
    // B: drag after drag while A's checkpoints block
    let start = Instant::now();
    let mut worst = Duration::ZERO;
    let mut seq = 0;
    while start.elapsed() < Duration::from_secs(3) {
        seq += 1;
        let sent = Instant::now();
        ws.drag(0, [0.0, 0.01, 0.0], None, seq).await?;
        loop {
            match ws.next().await? {
                WsEvent::Frame(h, _) if h.ack_seq >= seq => break,
                WsEvent::Event(e @ ServerMsg::Error { .. }) => panic!("drag {seq} refused: {e:?}"),
                WsEvent::Closed(c) => panic!("closed ({c:?}) waiting for drag {seq}"),
                _ => {}
            }
        }
        worst = worst.max(sent.elapsed());
        // a person's pace, under the server's message rate limit (a tiny
        // mesh answers a drag in well under the limit's 2 ms)
        tokio::time::sleep(Duration::from_millis(4)).await;
    }
    slow.await.expect("join")?;
    assert!(seq > 5, "only {seq} drags of B in 3 s");
    assert!(
        worst < Duration::from_millis(750),
        "B waited {worst:?} for a frame while A's store was slow (1.5 s writes)"
    );
    Ok(())
}

/// Uploads racing for the last `max_meshes` slots on a store whose count
/// takes 50 ms: exactly the limit is stored, every other upload gets 503
/// (the check and the insert are one admission step; with them apart all
/// twelve uploads read the same count and pass).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn concurrent_uploads_never_exceed_max_meshes() {
    let store = Arc::new(Slowness {
        slow: Mutex::new(None),
        delay: Duration::ZERO,
        count_delay: Duration::from_millis(50),
    });
    let config = Config {
        max_meshes: 3,
        ..Config::default()
    };
    let (base, _state) = start_with_store(config, slow_store(&store)).await;
    let (p, t) = grid(4);
    let body = MeshJson {
        positions: p,
        triangles: t,
    };
    let http = reqwest::Client::new();
    let uploads: Vec<_> = (0..12)
        .map(|_| {
            let (http, url, body) = (http.clone(), format!("{base}/v1/meshes"), body.clone());
            tokio::spawn(async move {
                http.post(url)
                    .json(&body)
                    .send()
                    .await
                    .map(|r| r.status().as_u16())
            })
        })
        .collect();
    let mut statuses = Vec::new();
    for u in uploads {
        statuses.push(u.await.expect("task").expect("request"));
    }
    let created = statuses.iter().filter(|&&s| s == 201).count();
    let refused = statuses.iter().filter(|&&s| s == 503).count();
    assert_eq!((created, refused), (3, 9), "{statuses:?}");
}

/// A memory store whose journal appends (or another operation, `op`) for
/// one session can be held: past the first `skip` such calls, the call
/// waits (at most 20 s) until `open` is set, after raising `entered`.
#[derive(Default)]
struct AppendGate {
    session: Mutex<Option<String>>,
    op: Mutex<Option<&'static str>>,
    skip: std::sync::atomic::AtomicUsize,
    entered: std::sync::atomic::AtomicBool,
    open: std::sync::atomic::AtomicBool,
}

impl AppendGate {
    /// `memory` behind the gate.
    fn store(self: &Arc<Self>, memory: Arc<dyn Store>) -> Arc<dyn Store> {
        use std::sync::atomic::Ordering;
        let g = self.clone();
        Arc::new(with_faults(memory, move |call| {
            let op = g.op.lock().unwrap_or("append");
            let mine = call.op == op && call.id.is_some() && g.session.lock().as_deref() == call.id;
            // (the first `skip` calls pass: `skip` counts down to 0)
            let skipped = mine
                && g.skip
                    .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |k| k.checked_sub(1))
                    .is_ok();
            if mine && !skipped {
                g.entered.store(true, Ordering::SeqCst);
                let until = Instant::now() + Duration::from_secs(20);
                while !g.open.load(Ordering::SeqCst) && Instant::now() < until {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
            Ok(())
        }))
    }

    /// Holds `session`'s appends from now on.
    fn hold(&self, session: &str) {
        *self.session.lock() = Some(session.to_owned());
    }

    /// Holds `session`'s calls of `op` from now on, past the first `skip`.
    fn hold_op(&self, session: &str, op: &'static str, skip: usize) {
        *self.op.lock() = Some(op);
        self.skip.store(skip, std::sync::atomic::Ordering::SeqCst);
        self.hold(session);
    }

    /// Whether a call is held (or was).
    fn was_entered(&self) -> bool {
        self.entered.load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Waits until an append is held.
    async fn entered(&self) {
        let start = Instant::now();
        while !self.was_entered() {
            assert!(
                start.elapsed() < Duration::from_secs(30),
                "no append was held"
            );
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }

    /// Opens the gate `after` from now, on a thread of its own (whatever
    /// the test's tasks wait for meanwhile).
    fn open_after(self: &Arc<Self>, after: Duration) -> std::thread::JoinHandle<()> {
        let g = self.clone();
        std::thread::spawn(move || {
            std::thread::sleep(after);
            g.open.store(true, std::sync::atomic::Ordering::SeqCst);
        })
    }
}

/// A ready 8×8 grid session on a server over `store` (`memory` beneath
/// it), whose constraint set's first settle is checkpointed (the history
/// entry an undo goes back to); the server lives as long as its state.
async fn gated_session(
    store: Arc<dyn Store>,
    memory: &Arc<dyn Store>,
) -> Result<(Arc<dend_client::SessionClient>, dend_server::AppState), ClientError> {
    let (base, state) = start_with_store(Config::default(), store).await;
    let c = Client::new(&base);
    let (p, t) = grid(8);
    let mesh = c.upload_json(&p, &t).await?;
    let s = Arc::new(c.create_session(&mesh.id, SessionParams::default()).await?);
    s.set_constraints(&grid_constraints(8)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    // the set's first solve settled, and so committed the first undo step:
    // the constraint edit writes a checkpoint when it is installed, before
    // that solve, and a drag sent while it still runs joins it (a loaded
    // host showed it: the test's undo then found the drag in the first
    // step, with nothing before it to go back to)
    let start = Instant::now();
    while !s.pose().await?.settled || memory.get_checkpoint(&s.id).expect("store").is_none() {
        assert!(
            start.elapsed() < Duration::from_secs(30),
            "no first settled pose and checkpoint"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    Ok((s, state))
}

/// [`gated_session`] on a memory store behind a fresh [`AppendGate`]:
/// the gate, the memory store, the session and the server's state.
async fn gated() -> Result<
    (
        Arc<AppendGate>,
        Arc<dyn Store>,
        Arc<dend_client::SessionClient>,
        dend_server::AppState,
    ),
    ClientError,
> {
    let gate = Arc::new(AppendGate::default());
    let memory: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let (s, state) = gated_session(gate.store(memory.clone()), &memory).await?;
    Ok((gate, memory, s, state))
}

/// The first frame's header on a new connection (within 10 s).
async fn first_frame(ws: &mut WsClient) -> Result<FrameHeader, ClientError> {
    loop {
        match tokio::time::timeout(Duration::from_secs(10), ws.next()).await {
            Ok(Ok(WsEvent::Frame(h, _))) => return Ok(h),
            Ok(Ok(_)) => {}
            Ok(Err(e)) => return Err(e),
            Err(_) => panic!("no first frame within 10 s"),
        }
    }
}

/// A client that sent drag 1 (0.1 up) before its connection dropped
/// follows the reconnect rule on its new connection `ws`: it sends the
/// drag again unless the first frame acknowledges it, then waits for a
/// settled frame that does. Returns the first frame's header.
async fn reconnect_rule(ws: &mut WsClient) -> Result<FrameHeader, ClientError> {
    let h0 = first_frame(ws).await?;
    if h0.ack_seq < 1 {
        ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    }
    if !(h0.ack_seq >= 1 && h0.converged) {
        let acked = tokio::time::timeout(Duration::from_secs(10), ws.frame_acking(1, true)).await;
        let _ = acked.unwrap_or_else(|_| panic!("no settled frame acknowledged drag 1"))?;
    }
    Ok(h0)
}

/// [`reconnect_rule`] for drag `seq` (`dz` up): sent again unless the
/// first frame acknowledges it, then a settled frame that does (the first
/// one itself, when it is). Returns the first frame's header.
async fn resend_unless_shown(
    ws: &mut WsClient,
    seq: u64,
    dz: f64,
) -> Result<FrameHeader, ClientError> {
    let h0 = first_frame(ws).await?;
    if h0.ack_seq < seq {
        ws.drag(0, [0.0, 0.0, dz], None, seq).await?;
    }
    if !(h0.ack_seq >= seq && h0.converged) {
        let acked = tokio::time::timeout(Duration::from_secs(20), ws.frame_acking(seq, true)).await;
        let _ = acked.unwrap_or_else(|_| panic!("no settled frame acknowledged drag {seq}"))?;
    }
    Ok(h0)
}

/// The handle (the grid's top row, rigid) moved `dz` up from `before` to
/// `after`; `why` is said when it did not.
fn assert_handle_moved(before: &Pose, after: &Pose, dz: f64, why: &str) {
    for v in 56..64 {
        let moved = after.positions[v][2] - before.positions[v][2];
        assert!(
            (moved - dz).abs() < 1e-9,
            "vertex {v} moved {moved}, not {dz} ({why})"
        );
    }
}

/// The handle moved by the one 0.1 drag from `before` to `after`; `h0` is
/// the new connection's first frame.
fn assert_moved_once(before: &Pose, after: &Pose, h0: &FrameHeader) {
    let why = format!(
        "first frame of the new connection acknowledged {}",
        h0.ack_seq
    );
    assert_handle_moved(before, after, 0.1, &why);
}

/// [`gated`] with two clients connected and their first frames read (a new
/// connection's first frame waits for the drags the session holds, and
/// its socket reads nothing before it), and the pose before any drag.
struct TwoClients {
    gate: Arc<AppendGate>,
    s: Arc<dend_client::SessionClient>,
    a: WsClient,
    b: WsClient,
    before: Pose,
    _state: dend_server::AppState,
}

async fn two_clients() -> Result<TwoClients, ClientError> {
    let (gate, _memory, s, _state) = gated().await?;
    let mut a = s.connect().await?;
    let _ = a.frame_acking(0, true).await?;
    let mut b = s.connect().await?;
    let _ = b.frame_acking(0, true).await?;
    let before = s.pose().await?;
    Ok(TwoClients {
        gate,
        s,
        a,
        b,
        before,
        _state,
    })
}

/// Runs `call` on a clone of `s` as a task of its own.
fn spawn_call<T, F>(
    s: &Arc<dend_client::SessionClient>,
    call: impl FnOnce(Arc<dend_client::SessionClient>) -> F,
) -> tokio::task::JoinHandle<Result<T, ClientError>>
where
    T: Send + 'static,
    F: std::future::Future<Output = Result<T, ClientError>> + Send + 'static,
{
    tokio::spawn(call(s.clone()))
}

/// Client `a`'s drag 1 (0.1 up) is held in its journal append; `command`
/// (a call that waits in the session) is sent then and given 300 ms to
/// reach the session; client `b`'s drag 2 (0.2 up) comes after it, and
/// the gate opens 300 ms later. Returns the pose once `command` returned
/// and a settled frame acknowledged drag 2.
async fn drag_behind<T: Send + 'static>(
    t: &mut TwoClients,
    command: tokio::task::JoinHandle<Result<T, ClientError>>,
) -> Result<Pose, ClientError> {
    tokio::time::sleep(Duration::from_millis(300)).await;
    t.b.drag(0, [0.0, 0.0, 0.2], None, 2).await?;
    let opener = t.gate.open_after(Duration::from_millis(300));
    let _ = command.await.expect("join")?;
    opener.join().expect("opener");
    let acked = tokio::time::timeout(Duration::from_secs(10), t.b.frame_acking(2, true)).await;
    let _ = acked.unwrap_or_else(|_| panic!("no settled frame acknowledged drag 2 within 10 s"))?;
    t.s.pose().await
}

/// Client `a`'s drag 1 (0.1 up), its journal append held at the gate.
async fn hold_drag_1(t: &mut TwoClients) -> Result<(), ClientError> {
    t.gate.hold(&t.s.id);
    t.a.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    t.gate.entered().await;
    Ok(())
}

/// `command` (a call that waits in the session) given 300 ms to reach the
/// session, client `b`'s drag 3 (0.2 up) held behind it; then `b`
/// reconnects and follows the reconnect rule while the gate opens
/// `open_after` later. Once `command` returned and the session is ready,
/// the handle has moved `dz` from the pose before any drag: the held drag
/// applied once.
async fn held_drag_applied_once<T: Send + 'static>(
    t: TwoClients,
    command: tokio::task::JoinHandle<Result<T, ClientError>>,
    open_after: Duration,
    dz: f64,
) -> Result<(), ClientError> {
    let TwoClients {
        gate,
        s,
        mut b,
        before,
        ..
    } = t;
    tokio::time::sleep(Duration::from_millis(300)).await;
    b.drag(0, [0.0, 0.0, 0.2], None, 3).await?;
    tokio::time::sleep(Duration::from_millis(100)).await;
    drop(b);
    let opener = gate.open_after(open_after);
    let mut b2 = s.connect().await?;
    let h0 = resend_unless_shown(&mut b2, 3, 0.2).await?;
    let _ = command.await.expect("join")?;
    opener.join().expect("opener");
    s.wait_ready(Duration::from_secs(60)).await?;
    let after = s.pose().await?;
    let why = format!("first frame acknowledged {}", h0.ack_seq);
    assert_handle_moved(&before, &after, dz, &why);
    Ok(())
}

/// An undo that arrives while the solve of the drag before it is still
/// writing that drag to the journal: the store ends with the undone state,
/// as a revival would rebuild it (the checkpoint's targets, then the
/// journal after it). The append is held at a gate until the undo is in.
/// The undo waits for the running solve, so its checkpoint (which
/// truncates the journal) comes after the append; an undo served at once
/// (measured by taking it off the commands that wait) checkpoints first,
/// the drag lands in the journal after the checkpoint, and a revival
/// replays the drag the user took back.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_undo_racing_a_journal_append_is_not_undone_by_a_revival() -> Result<(), ClientError> {
    let (gate, memory, s, _state) = gated().await?;

    gate.hold(&s.id);
    let dragged = {
        let s = s.clone();
        tokio::spawn(async move { s.drag(0, DeltaJson::translate([0.0, 0.0, 0.3]), None).await })
    };
    gate.entered().await;
    // the append is held: the undo comes in now, and the gate opens a
    // little later whether or not the undo waits for it
    let opener = gate.open_after(Duration::from_millis(300));
    s.undo().await?;
    let _ = dragged.await.expect("join");
    opener.join().expect("opener");

    let cp = memory
        .get_checkpoint(&s.id)
        .expect("store")
        .expect("a checkpoint");
    let journal = memory.journal(&s.id).expect("store");
    // pure translations compose by adding
    let mut z = cp.targets[0].translation[2];
    for e in &journal {
        let dend_server::store::JournalEntry::Drag {
            handle,
            translation,
            ..
        } = e;
        if *handle == 0 {
            z += translation[2];
        }
    }
    assert!(
        z.abs() < 1e-12,
        "a revival rebuilds the handle 0.3 up, the undone drag (checkpoint {}, journal {journal:?})",
        cp.targets[0].translation[2]
    );
    Ok(())
}

/// A drag that arrives while a solve runs, then an undo on the same
/// socket: the undo takes the drag back before any solve applies it, and
/// its frame acknowledges the drag. A frame that acknowledged only the
/// solved drags left the taken-back one pending in the client, which
/// resends pending drags after a reconnect: on top of the undone pose.
/// The first drag's append is held at a gate so that the second one
/// arrives while its solve runs.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_undo_acknowledges_the_drags_it_takes_back() -> Result<(), ClientError> {
    let (gate, _memory, s, _state) = gated().await?;
    let mut ws = s.connect().await?;
    let _ = ws.frame_acking(0, true).await?;
    let before = s.pose().await?;

    gate.hold(&s.id);
    ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    gate.entered().await;
    ws.drag(0, [0.0, 0.0, 0.1], None, 2).await?;
    ws.send(&dend_client::ws::ClientMsg::Undo).await?;
    let opener = gate.open_after(Duration::from_millis(200));
    let acked = tokio::time::timeout(Duration::from_secs(10), ws.frame_acking(2, true)).await;
    opener.join().expect("opener");
    let (h, _) = acked.unwrap_or_else(|_| panic!("no frame acknowledged drag 2 within 10 s"))?;
    assert!(h.settled, "{h:?}");
    // the pose is the undone one, the history entry's
    let after = s.pose().await?;
    assert_eq!(after.positions, before.positions);
    Ok(())
}

/// A client that reconnects while its last drag is received but not yet
/// solved, and follows the reconnect rule (resend the drags the first
/// frame does not acknowledge), has the drag applied once. The drag's
/// journal append is held at a gate while the second connection opens, so
/// that the session has the drag in its targets and no frame for it yet.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_reconnect_during_a_drags_solve_does_not_apply_it_twice() -> Result<(), ClientError> {
    let (gate, _memory, s, _state) = gated().await?;
    let mut first = s.connect().await?;
    let _ = first.frame_acking(0, true).await?;
    let before = s.pose().await?;

    gate.hold(&s.id);
    first.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    gate.entered().await;
    // the connection drops; the client opens another one
    drop(first);
    let opener = gate.open_after(Duration::from_millis(300));
    let h0 = reconnect_rule(&mut s.connect().await?).await?;
    opener.join().expect("opener");
    assert_moved_once(&before, &s.pose().await?, &h0);
    Ok(())
}

/// A pose read while a drag is being solved (a reconnecting client's
/// fallback when no frame comes) acknowledges the drag: the read waits for
/// it, as the first frame of a new connection does.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_pose_read_during_a_drags_solve_acknowledges_it() -> Result<(), ClientError> {
    let (gate, _memory, s, _state) = gated().await?;
    let mut ws = s.connect().await?;
    let _ = ws.frame_acking(0, true).await?;
    gate.hold(&s.id);
    ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    gate.entered().await;
    let opener = gate.open_after(Duration::from_millis(300));
    let pose = s.pose().await?;
    opener.join().expect("opener");
    assert_eq!(pose.ack_seq, 1, "the pose read while drag 1 was solved");
    Ok(())
}

/// A client that joins while another one drags without pause gets its
/// first frame while the other still drags: the wait for the drags no
/// frame shows yet ends with the solve that takes the ones received
/// before the join, not with a pause in the stream. Each journal append
/// takes 20 ms and a drag comes every 5 ms, so some drag always waits for
/// a frame (measured: a wait for none left held the first frame until
/// the stream ended).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_joining_a_stream_of_drags_gets_its_first_frame() -> Result<(), ClientError> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let memory: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let slow: Arc<dyn Store> = Arc::new(with_faults(memory.clone(), |call| {
        if call.op == "append" {
            std::thread::sleep(Duration::from_millis(20));
        }
        Ok(())
    }));
    let (s, _state) = gated_session(slow, &memory).await?;
    let joined = Arc::new(AtomicBool::new(false));
    let dragging = {
        let (s, joined) = (s.clone(), joined.clone());
        tokio::spawn(async move {
            let mut ws = s.connect().await?;
            let _ = ws.frame_acking(0, true).await?;
            let start = Instant::now();
            let mut seq = 0;
            // a drag every 5 ms (under the message rate limit), until the
            // other client has its first frame or 8 s have passed
            while !joined.load(Ordering::SeqCst) && start.elapsed() < Duration::from_secs(8) {
                seq += 1;
                ws.drag(0, [0.0, 0.0, 0.001], None, seq).await?;
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
            Ok::<bool, ClientError>(joined.load(Ordering::SeqCst))
        })
    };
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut second = s.connect().await?;
    loop {
        match second.next().await? {
            WsEvent::Frame(..) => break,
            WsEvent::Closed(c) => panic!("closed ({c:?}) before a first frame"),
            _ => {}
        }
    }
    joined.store(true, Ordering::SeqCst);
    let still_dragging = dragging.await.expect("join")?;
    assert!(
        still_dragging,
        "the first frame came only after the other client's 8 s of drags"
    );
    Ok(())
}

/// A drag that waits in the session's command queue (the session busy
/// with a store write, a named pose's save held at a gate) when its
/// client reconnects: the first frame of the new connection acknowledges
/// it, and the client following the reconnect rule does not send it
/// twice (measured: asked of the session's state instead of through its
/// queue, the first frame acknowledged 0 and the handle moved 0.2).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_queued_behind_a_store_write_is_not_applied_twice() -> Result<(), ClientError> {
    let (gate, _memory, s, _state) = gated().await?;
    let mut first = s.connect().await?;
    let _ = first.frame_acking(0, true).await?;
    let before = s.pose().await?;
    gate.hold_op(&s.id, "put_named_pose", 0);
    let saving = {
        let s = s.clone();
        tokio::spawn(async move { s.save_pose("p", false).await })
    };
    gate.entered().await;
    first.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    // the drag reaches the session's queue, behind the held save
    tokio::time::sleep(Duration::from_millis(100)).await;
    drop(first);
    let opener = gate.open_after(Duration::from_millis(300));
    let h0 = reconnect_rule(&mut s.connect().await?).await?;
    opener.join().expect("opener");
    let _ = saving.await.expect("join")?;
    assert_moved_once(&before, &s.pose().await?, &h0);
    Ok(())
}

/// A session closed while a drag's solve runs: a pose read on a handle
/// taken before the close, and so a connection's first frame, return at
/// once (measured with the wait on a flag the closed session no longer
/// updated: the read took the whole safety bound).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_closed_session_answers_a_pose_read_at_once() -> Result<(), ClientError> {
    let (gate, _memory, s, state) = gated().await?;
    let h = state.registry.get(&s.id).expect("a live session");
    let mut ws = s.connect().await?;
    let _ = ws.frame_acking(0, true).await?;
    gate.hold(&s.id);
    ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    gate.entered().await;
    h.close().await;
    let opener = gate.open_after(Duration::from_millis(300));
    tokio::time::sleep(Duration::from_millis(600)).await;
    let t0 = Instant::now();
    let read = tokio::time::timeout(Duration::from_secs(90), h.pose()).await;
    let took = t0.elapsed();
    opener.join().expect("opener");
    assert!(
        read.is_ok(),
        "a pose read of the closed session did not return"
    );
    assert!(
        took < dend_server::session::DRAGS_SHOWN_WAIT,
        "a pose read of the closed session took the wait's whole bound ({took:?})"
    );
    Ok(())
}

/// A constraint edit keeps the drags received before it: it waits for
/// their solve, then commits that pose as an undo step and anchors the new
/// set there. Before, it committed the step with the drags in its targets
/// but not in its pose, and took them back from the new set. Drag 1's
/// append is held so that drag 2 is received, not yet solved, when the
/// edit (which waits for the running solve) comes in.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_constraint_edit_keeps_the_drags_received_before_it() -> Result<(), ClientError> {
    let (gate, _memory, s, _state) = gated().await?;
    let mut ws = s.connect().await?;
    let _ = ws.frame_acking(0, true).await?;
    let before = s.pose().await?;
    gate.hold(&s.id);
    ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    gate.entered().await;
    ws.drag(0, [0.0, 0.0, 0.1], None, 2).await?;
    // drag 2 reaches the session before the edit
    tokio::time::sleep(Duration::from_millis(100)).await;
    let opener = gate.open_after(Duration::from_millis(300));
    let edit = {
        let s = s.clone();
        tokio::spawn(async move { s.set_constraints(&grid_constraints(8)).await })
    };
    let _ = edit.await.expect("join")?;
    opener.join().expect("opener");
    s.wait_ready(Duration::from_secs(60)).await?;
    let acked = tokio::time::timeout(Duration::from_secs(10), ws.frame_acking(2, true)).await;
    let _ = acked.unwrap_or_else(|_| panic!("no settled frame acknowledged drag 2 within 10 s"))?;
    let edited = s.pose().await?;
    // the undo step the edit committed: its pose holds both drags too
    let undone = s.undo().await?;
    assert_handle_moved(&before, &edited, 0.2, "after the edit");
    assert_handle_moved(&before, &undone, 0.2, "the edit's undo step");
    Ok(())
}

/// Another client's drag that reaches the session after an undo, while the
/// undo waits for the running solve of the drag before it: the drag is
/// applied after the undo, on the undone pose. Served at once, it went
/// into the targets the undo then replaced: lost, while its frame
/// acknowledged it. The first drag's append is held at a gate so that the
/// undo and the second client's drag both arrive while its solve runs.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_after_a_waiting_undo_is_applied_after_it() -> Result<(), ClientError> {
    let mut t = two_clients().await?;
    hold_drag_1(&mut t).await?;
    let undo = spawn_call(&t.s, |s| async move { s.undo().await });
    let after = drag_behind(&mut t, undo).await?;
    // drag 2 alone: lost, the handle would not move; applied before the
    // undo, it would have been taken back with drag 1
    assert_handle_moved(&t.before, &after, 0.2, "drag 2 after the undo");
    Ok(())
}

/// Another client's drag that reaches the session after a constraint
/// edit, while the edit waits for the running solve of the drag before
/// it: the drag is applied to the new set, after the edit. Served at
/// once, it went into the old set's targets, which the new set replaced:
/// lost, while its frame acknowledged it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_after_a_waiting_constraint_edit_moves_the_new_set() -> Result<(), ClientError> {
    let mut t = two_clients().await?;
    hold_drag_1(&mut t).await?;
    let edit = spawn_call(&t.s, |s| async move {
        s.set_constraints(&grid_constraints(8)).await
    });
    let after = drag_behind(&mut t, edit).await?;
    // both drags: the edit anchors the new set where drag 1 left the pose,
    // and drag 2 moves it from there
    assert_handle_moved(&t.before, &after, 0.3, "drag 2 on the new set");
    Ok(())
}

/// Another client's drag that reaches the session after a named pose's
/// restore, while the restore waits for the settle of the drag before
/// it: the drag is applied after the restore, on the restored pose.
/// Served at once, it went into the targets the restore then replaced.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_after_a_waiting_restore_is_applied_after_it() -> Result<(), ClientError> {
    let mut t = two_clients().await?;
    t.s.save_pose("start", false).await?;
    hold_drag_1(&mut t).await?;
    let restore = spawn_call(&t.s, |s| async move { s.restore_pose("start").await });
    let after = drag_behind(&mut t, restore).await?;
    assert_handle_moved(&t.before, &after, 0.2, "drag 2 after the restore");
    Ok(())
}

/// A constraint edit after a solve that failed while drags arrived: those
/// drags get a solve of their own, and the edit (which waits for the
/// solve of the drags received before it) returns. The failing solve is
/// made by two huge, finite drags whose composed target overflows; drag
/// 1's append is held so that they compose while its solve runs, and the
/// failing solve's append so that drag 4 arrives during it. Before, the
/// failed solve marked the pose settled, no solve took drag 4, and the
/// edit waited for ever.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_constraint_edit_after_a_failed_solve_returns() -> Result<(), ClientError> {
    let (first, second) = (
        Arc::new(AppendGate::default()),
        Arc::new(AppendGate::default()),
    );
    let memory: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let held = second.store(first.store(memory.clone()));
    let (s, _state) = gated_session(held, &memory).await?;
    let mut ws = s.connect().await?;
    let _ = ws.frame_acking(0, true).await?;
    first.hold(&s.id);
    second.hold_op(&s.id, "append", 1);
    ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
    first.entered().await;
    ws.drag(0, [1e308, 0.0, 0.0], None, 2).await?;
    ws.drag(0, [1e308, 0.0, 0.0], None, 3).await?;
    tokio::time::sleep(Duration::from_millis(100)).await;
    first.open_after(Duration::ZERO).join().expect("open");
    second.entered().await;
    ws.drag(0, [0.0, 0.0, 0.1], None, 4).await?;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let edit = {
        let s = s.clone();
        tokio::spawn(async move { s.set_constraints(&grid_constraints(8)).await })
    };
    tokio::time::sleep(Duration::from_millis(300)).await;
    second.open_after(Duration::ZERO).join().expect("open");
    let done = tokio::time::timeout(Duration::from_secs(15), edit).await;
    let _ = done
        .unwrap_or_else(|_| panic!("the constraint edit did not return within 15 s"))
        .expect("join")?;
    Ok(())
}

/// A client that reconnects while its drag waits behind a constraint edit
/// (which waits for the solve of the drags before it), and follows the
/// reconnect rule, has the drag applied once: the new connection's first
/// frame waits for the held drag's own solve. Before, a solve that ended
/// while the drag was held answered that wait, the first frame did not
/// acknowledge the drag, and the client's resend moved the handle twice.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_held_behind_an_edit_is_not_applied_twice() -> Result<(), ClientError> {
    let mut t = two_clients().await?;
    hold_drag_1(&mut t).await?;
    t.a.drag(0, [0.0, 0.0, 0.1], None, 2).await?;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let edit = spawn_call(&t.s, |s| async move {
        s.set_constraints(&grid_constraints(8)).await
    });
    held_drag_applied_once(t, edit, Duration::from_millis(1000), 0.4).await
}

/// The same behind a named pose's restore, which waits for the settle:
/// the settle's solves end while the drag is held.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_held_behind_a_restore_is_not_applied_twice() -> Result<(), ClientError> {
    let mut t = two_clients().await?;
    t.s.save_pose("start", false).await?;
    hold_drag_1(&mut t).await?;
    let restore = spawn_call(&t.s, |s| async move { s.restore_pose("start").await });
    held_drag_applied_once(t, restore, Duration::from_millis(300), 0.2).await
}

/// The commands that wait keep their arrival order: drag 1, an undo
/// (waits for drag 1's solve), another client's drag 3 (held behind the
/// undo), then a named pose's restore. The restore comes last, so the
/// pose is the named one. Before, a restore waited apart from the held
/// drags, ran first, and drag 3 was applied after it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_before_a_restore_is_not_applied_after_it() -> Result<(), ClientError> {
    let mut t = two_clients().await?;
    t.s.save_pose("start", false).await?;
    hold_drag_1(&mut t).await?;
    let undo = spawn_call(&t.s, |s| async move { s.undo().await });
    tokio::time::sleep(Duration::from_millis(300)).await;
    t.b.drag(0, [0.0, 0.0, 0.2], None, 3).await?;
    tokio::time::sleep(Duration::from_millis(100)).await;
    let restore = spawn_call(&t.s, |s| async move { s.restore_pose("start").await });
    tokio::time::sleep(Duration::from_millis(300)).await;
    let opener = t.gate.open_after(Duration::from_millis(100));
    let _ = undo.await.expect("join")?;
    let _ = restore.await.expect("join")?;
    opener.join().expect("opener");
    let acked = tokio::time::timeout(Duration::from_secs(10), t.b.frame_acking(3, true)).await;
    let _ = acked.unwrap_or_else(|_| panic!("no settled frame acknowledged drag 3"))?;
    let after = t.s.pose().await?;
    assert_handle_moved(&t.before, &after, 0.0, "the restore came last");
    Ok(())
}
