//! The clients of the failover test (tests/system/failover.rs): each drags one
//! session over WebSocket through HAProxy and keeps a [`Tally`] of what the
//! servers acknowledged, reconnecting whenever its connection fails.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use dend_client::ws::{ClientMsg, ServerMsg};
use dend_client::{ErrorCode, SessionClient, WsEvent};
use parking_lot::Mutex;

/// The x translation of drag `seq` (distinct per seq, so the final pose
/// tells which drags it holds).
pub fn dx(seq: u64) -> f64 {
    0.001 * (1 + seq % 5) as f64
}

/// What one client saw.
#[derive(Default, Debug)]
pub struct Tally {
    /// Highest sequence number acknowledged by a frame.
    pub acked: u64,
    /// Drags acknowledged (each seq once).
    pub drags: u64,
    /// Acknowledged before a failure but missing after it (must stay 0).
    pub lost: u64,
    /// Each reconnection after a kill of the owner: time from the kill to
    /// the first frame served again.
    pub recoveries: Vec<Duration>,
    /// Each reconnection after the owner was frozen (SIGSTOP): time from
    /// the freeze to the first frame served again.
    pub freeze_recoveries: Vec<Duration>,
    /// Each other reconnection (a hand-over to a returning instance): time
    /// from the client noticing to the first frame.
    pub other_reconnections: Vec<Duration>,

    /// Store errors seen as events while PostgreSQL was down.
    pub store_errors: u64,
}

/// How a session's owner was taken away.
#[derive(Clone, Copy)]
pub enum Cut {
    /// SIGKILL.
    Kill,
    /// SIGSTOP (alive, silent).
    Freeze,
}

/// What the clients share with the test.
pub struct Shared {
    /// Set to end the clients.
    pub stop: AtomicBool,
    /// The sessions whose owner was killed, with the time of the kill,
    /// until their client gets a frame again.
    pub affected: Mutex<HashMap<String, (Instant, Cut)>>,
}

/// How the server answered one drag.
enum Answer {
    /// A frame acknowledged it (and everything before): the acked seq.
    Acked(u64),
    /// An `error` event `store_unavailable`: not applied.
    Refused,
    /// The connection failed or went silent.
    Broken,
}

/// One client: drags one at a time, each acknowledged by a frame before
/// the next; on any failure reconnects through HAProxy and resumes after
/// the acknowledged sequence number the server reports.
pub async fn drive(
    s: SessionClient,
    shared: Arc<Shared>,
    tally: Arc<Mutex<Tally>>,
) -> Result<(), String> {
    let mut seq_next;
    let mut down_since: Option<Instant> = None;
    'connect: while !shared.stop.load(Ordering::Relaxed) {
        // a frozen instance (SIGSTOP) still completes TCP handshakes from
        // its listen backlog but never answers the upgrade, and HAProxy
        // waits `timeout server` (60 s) for it: give up after 5 s, as a
        // real client would, and go through HAProxy again (by then it has
        // marked the instance down)
        let mut ws = match tokio::time::timeout(Duration::from_secs(5), s.connect()).await {
            Ok(Ok(ws)) => ws,
            Ok(Err(_)) | Err(_) => {
                down_since.get_or_insert_with(Instant::now);
                tokio::time::sleep(Duration::from_millis(50)).await;
                continue;
            }
        };
        // the first frame says what the (possibly new) owner holds
        let first = tokio::time::timeout(Duration::from_secs(30), async {
            loop {
                match ws.next().await {
                    Ok(WsEvent::Frame(h, _)) => return Some(h),
                    Ok(WsEvent::Closed(_)) | Err(_) => return None,
                    Ok(WsEvent::Event(_)) => {}
                }
            }
        })
        .await;
        let Ok(Some(h)) = first else {
            down_since.get_or_insert_with(Instant::now);
            continue 'connect;
        };
        {
            let mut t = tally.lock();
            if h.ack_seq < t.acked {
                t.lost += t.acked - h.ack_seq;
            }
            if let Some(since) = down_since.take() {
                // was its session on the instance that was killed?
                match shared.affected.lock().remove(&s.id) {
                    Some((at, Cut::Kill)) => t.recoveries.push(at.elapsed()),
                    Some((at, Cut::Freeze)) => t.freeze_recoveries.push(at.elapsed()),
                    None => t.other_reconnections.push(since.elapsed()),
                }
            }
            t.acked = t.acked.max(h.ack_seq);
            seq_next = t.acked + 1;
        }
        // hold the handle, as the editor does during a gesture: the session
        // checkpoints only when a gesture ends, so until then the
        // acknowledged drags exist in the journal alone
        if ws
            .send(&ClientMsg::Grab { handle: 0.into() })
            .await
            .is_err()
        {
            down_since.get_or_insert_with(Instant::now);
            continue 'connect;
        }
        while !shared.stop.load(Ordering::Relaxed) {
            let seq = seq_next;
            if seq % 40 == 0 {
                // end the gesture (a checkpoint), start the next
                let release = ws.send(&ClientMsg::Release { handle: 0.into() }).await;
                if release.is_err()
                    || ws
                        .send(&ClientMsg::Grab { handle: 0.into() })
                        .await
                        .is_err()
                {
                    down_since.get_or_insert_with(Instant::now);
                    continue 'connect;
                }
            }
            if ws.drag(0, [dx(seq), 0.0, 0.0], None, seq).await.is_err() {
                down_since.get_or_insert_with(Instant::now);
                continue 'connect;
            }
            let answer = tokio::time::timeout(Duration::from_secs(5), async {
                loop {
                    match ws.next().await {
                        Ok(WsEvent::Frame(h, _)) if h.ack_seq >= seq => {
                            return Answer::Acked(h.ack_seq)
                        }
                        // refused, not applied (the store is down): send it again
                        Ok(WsEvent::Event(ServerMsg::Error {
                            code: ErrorCode::StoreUnavailable,
                            ..
                        })) => {
                            return Answer::Refused;
                        }
                        Ok(WsEvent::Closed(_)) | Err(_) => return Answer::Broken,
                        _ => {}
                    }
                }
            })
            .await
            .unwrap_or(Answer::Broken);
            match answer {
                Answer::Acked(a) => {
                    let mut t = tally.lock();
                    t.drags += a.saturating_sub(t.acked);
                    t.acked = t.acked.max(a);

                    seq_next = t.acked + 1;
                }
                Answer::Refused => {
                    tally.lock().store_errors += 1;
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
                Answer::Broken => {
                    down_since.get_or_insert_with(Instant::now);
                    continue 'connect;
                }
            }
            tokio::time::sleep(Duration::from_millis(15)).await;
        }
        let _ = ws.close().await;
    }
    Ok(())
}
