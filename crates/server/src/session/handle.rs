//! [`SessionHandle`]: the shared, cloneable front of a session actor.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use parking_lot::Mutex;
use tokio::sync::{broadcast, mpsc, oneshot, watch};

use super::actor::Actor;
use super::error::SessionError;
use super::recovery::Recovered;
pub use super::shared::SessionOptions;
use super::shared::{Cmd, Grabs, Inner, Ownership, Presence, Restore, Shared};
use super::timing::DRAGS_SHOWN_WAIT;
use super::types::{wire_stage, Delta, Event, Frame, PoseSnapshot};
use dend::deform::{ConstraintsSpec, Params, Rest};
use dend_protocol::ws::{ClientId, HandleRef, PeerEvent, SessionInfo, SessionState};

/// A cloneable handle to a running session actor.
#[derive(Clone)]
pub struct SessionHandle {
    inner: Arc<Inner>,
}

impl SessionHandle {
    /// Starts the actor of a new session (no constraints yet).
    pub fn spawn(
        id: String,
        mesh_id: String,
        token_sha256: [u8; 32],
        rest: Arc<Rest>,
        params: Params,
        opts: SessionOptions,
    ) -> SessionHandle {
        let (cmd_tx, cmd_rx) = mpsc::channel(1024);
        let (frames_tx, frames) = watch::channel(None);
        let (events, _) = broadcast::channel(256);
        let inner = Arc::new(Inner {
            id,
            mesh_id,
            token_sha256,
            params,
            rest,
            cmd_tx,
            frames,
            events,
            shared: Mutex::new(Shared {
                state: SessionState::Empty,
                revision: 0,
                handles: vec![],
                grabs: Grabs::default(),
                can_undo: false,
                can_redo: false,
                constraints: None,
                constraints_revision: 0,
                warnings: Arc::default(),
                build_stage: None,
                poses: Arc::default(),
            }),
            presence: Presence {
                started: Instant::now(),
                last_active_ms: AtomicU64::new(0),
                clients: AtomicUsize::new(0),
                next_client: AtomicU64::new(1),
            },
            ownership: Ownership {
                fence: opts.fence,
                fenced: std::sync::atomic::AtomicBool::new(false),
                moving: std::sync::atomic::AtomicBool::new(false),
            },
        });
        let actor = Actor::new(inner.clone(), frames_tx, opts);
        drop(tokio::spawn(actor.run(cmd_rx)));
        SessionHandle { inner }
    }

    /// Whether a store write was refused because another instance took the
    /// session's lease over: the session no longer runs here.
    pub fn is_fenced(&self) -> bool {
        self.inner.ownership.fenced.load(Ordering::Relaxed)
    }

    /// Marks the session as handed over to another instance: when it
    /// closes here, its WebSocket clients are told to reconnect at once
    /// (close code `CLOSE_RECONNECT`), not that it was closed.
    pub fn mark_moving(&self) {
        self.inner.ownership.moving.store(true, Ordering::Relaxed);
    }

    /// Whether the session is being handed over (see [`mark_moving`](Self::mark_moving)).
    pub fn is_moving(&self) -> bool {
        self.inner.ownership.moving.load(Ordering::Relaxed)
    }

    /// The lease revision the session runs under (its fencing token).
    pub fn fence(&self) -> crate::store::Fence {
        self.inner.ownership.fence
    }

    /// Session id.
    pub fn id(&self) -> &str {
        &self.inner.id
    }

    /// SHA-256 of the access token.
    pub fn token_sha256(&self) -> &[u8; 32] {
        &self.inner.token_sha256
    }

    /// The solver parameters.
    pub fn params(&self) -> &Params {
        &self.inner.params
    }

    /// The rest mesh precomputation.
    pub fn rest(&self) -> &Arc<Rest> {
        &self.inner.rest
    }

    /// Public state.
    pub fn info(&self) -> SessionInfo {
        let s = self.inner.shared.lock();
        SessionInfo {
            id: self.inner.id.clone(),
            mesh_id: self.inner.mesh_id.clone(),
            state: s.state,
            revision: s.revision,
            handles: s.handles.clone(),
            peers: self.inner.presence.clients.load(Ordering::Relaxed),
            can_undo: s.can_undo,
            can_redo: s.can_redo,
            vertices: self.inner.rest.mesh().num_vertices(),
            constraints: s.constraints.as_deref().cloned(),
            constraints_revision: s.constraints_revision,
            warnings: s.warnings.to_vec(),
            build_stage: s.build_stage.map(wire_stage),
            poses: s.poses.to_vec(),
        }
    }

    /// Marks activity now (for the idle timeout).
    pub fn touch(&self) {
        let ms = self.inner.presence.started.elapsed().as_millis() as u64;
        self.inner
            .presence
            .last_active_ms
            .store(ms, Ordering::Relaxed);
    }

    /// Whether the session had no activity and no client for `timeout`.
    pub fn is_idle(&self, timeout: std::time::Duration) -> bool {
        let now = self.inner.presence.started.elapsed().as_millis() as u64;
        let last = self.inner.presence.last_active_ms.load(Ordering::Relaxed);
        self.inner.presence.clients.load(Ordering::Relaxed) == 0
            && now.saturating_sub(last) >= timeout.as_millis() as u64
    }

    /// Resolves a handle reference to its index.
    pub fn handle_index(&self, h: &HandleRef) -> Result<usize, SessionError> {
        let s = self.inner.shared.lock();
        let idx = match h {
            HandleRef::Index(i) => Some(*i).filter(|i| *i < s.handles.len()),
            HandleRef::Name(n) => s.handles.iter().position(|x| x == n),
        };
        idx.ok_or_else(|| SessionError::UnknownHandle { handle: h.clone() })
    }

    fn check_drag(
        &self,
        client: Option<ClientId>,
        h: &HandleRef,
        d: &Delta,
    ) -> Result<usize, SessionError> {
        if !d.translation.iter().all(|x| x.is_finite()) {
            return Err(SessionError::NonFinite {
                what: "translate".into(),
            });
        }
        if !d.rotation.coords.iter().all(|x| x.is_finite()) {
            return Err(SessionError::NonFinite {
                what: "rotate".into(),
            });
        }
        let state = self.inner.shared.lock().state;
        // while the factor builds the drag is queued and applied once it is
        // ready (`SessionOptions::build_wait`)
        if !matches!(state, SessionState::Ready | SessionState::Building) {
            return Err(SessionError::NotReady { state });
        }
        let idx = self.handle_index(h)?;
        if let Some(holder) = self.inner.shared.lock().grabs.holder(idx) {
            if Some(holder) != client {
                return Err(SessionError::HandleGrabbed { handle: h.clone() });
            }
        }
        Ok(idx)
    }

    async fn send(&self, cmd: Cmd) -> Result<(), SessionError> {
        self.touch();
        self.inner
            .cmd_tx
            .send(cmd)
            .await
            .map_err(|_| SessionError::Closed)
    }

    pub(super) async fn call<T>(
        &self,
        make: impl FnOnce(oneshot::Sender<Result<T, SessionError>>) -> Cmd,
    ) -> Result<T, SessionError> {
        let (tx, rx) = oneshot::channel();
        self.send(make(tx)).await?;
        rx.await.map_err(|_| SessionError::Closed)?
    }

    /// Queues a drag delta (WebSocket path): composed into the handle's
    /// target; the frame acknowledging `seq` follows (while the factor is
    /// being built, the first frame once it is ready). Returns once queued.
    pub async fn drag(
        &self,
        client: ClientId,
        h: &HandleRef,
        delta: Delta,
        seq: u64,
    ) -> Result<(), SessionError> {
        let handle = self.check_drag(Some(client), h, &delta)?;
        self.send(Cmd::Drag {
            handle,
            delta,
            seq,
            reply: None,
        })
        .await
    }

    /// Applies a drag delta and runs up to `max_iters` iterations (HTTP path),
    /// returning the resulting pose; while the factor is being built, waits
    /// for it (up to `SessionOptions::build_wait`).
    pub async fn drag_solve(
        &self,
        h: &HandleRef,
        delta: Delta,
        max_iters: usize,
    ) -> Result<PoseSnapshot, SessionError> {
        let handle = self.check_drag(None, h, &delta)?;
        self.call(|tx| Cmd::Drag {
            handle,
            delta,
            seq: 0,
            reply: Some((max_iters, tx)),
        })
        .await
    }

    /// Parses a constraints spec; the session resolves it against the mesh
    /// at its current pose, then starts building its factor in the
    /// background (state `building`).
    ///
    /// With `if_revision`, the edit applies only if the session's
    /// constraints revision still is that one ([`SessionError::StaleConstraints`]
    /// otherwise): the rule for concurrent edits.
    pub async fn set_constraints(
        &self,
        spec_json: serde_json::Value,
        if_revision: Option<u64>,
    ) -> Result<SessionState, SessionError> {
        let spec: ConstraintsSpec = serde_json::from_value(spec_json)
            .map_err(|e| SessionError::InvalidConstraints(e.to_string()))?;
        self.call(|reply| Cmd::SetConstraints {
            spec,
            if_revision,
            reply,
        })
        .await
    }

    /// Re-opens the stored constraints `spec_json` of a session read back
    /// from the store, with the [`Recovered`] targets and pose (see
    /// `server::recover`): parsed and resolved here, off the actor; the
    /// factor builds as after [`set_constraints`](Self::set_constraints).
    /// Stored data that does not fit is
    /// [`StoreError::Corrupt`](crate::store::StoreError::Corrupt).
    pub async fn restore(
        &self,
        spec_json: serde_json::Value,
        rec: Recovered,
    ) -> Result<SessionState, SessionError> {
        let corrupt = |reason: String| crate::store::StoreError::Corrupt {
            what: format!("constraints of session `{}`", self.inner.id),
            reason,
        };
        let spec: ConstraintsSpec =
            serde_json::from_value(spec_json.clone()).map_err(|e| corrupt(e.to_string()))?;
        let rest = self.inner.rest.clone();
        let restore = tokio::task::spawn_blocking(move || -> Result<_, SessionError> {
            let mut constraints = spec.resolve(rest.mesh())?;
            rec.apply(&mut constraints)?;
            Ok(Restore {
                stored: spec_json,
                spec,
                constraints,
                pose: rec.pose(rest.mesh().num_vertices()),
                ack_seq: rec.ack_seq,
            })
        })
        .await
        .map_err(|_| SessionError::Closed)??;
        self.call(|reply| Cmd::Restore { restore, reply }).await
    }

    /// Steps back in the history.
    pub async fn undo(&self) -> Result<PoseSnapshot, SessionError> {
        self.call(Cmd::Undo).await
    }

    /// Steps forward in the history.
    pub async fn redo(&self) -> Result<PoseSnapshot, SessionError> {
        self.call(Cmd::Redo).await
    }

    /// Back to the rest pose with identity handle targets (undoable).
    pub async fn reset(&self) -> Result<PoseSnapshot, SessionError> {
        self.call(Cmd::Reset).await
    }

    /// The current pose.
    pub async fn pose(&self) -> Result<PoseSnapshot, SessionError> {
        // its `ack_seq` is what a reconnecting client resends after
        self.drags_shown(DRAGS_SHOWN_WAIT).await;
        self.call(Cmd::Pose).await
    }

    /// Waits (at most `within`) until the drags the session had received
    /// when called are in a frame: none is left, or a solve that started
    /// since has ended (it took every drag received before it; drags that
    /// others send meanwhile do not prolong the wait). The question goes
    /// through the session's command queue, so it also covers drags still
    /// queued there (the session busy with a store write). A client that
    /// reconnects resends the drags its first frame (or the pose it reads)
    /// does not acknowledge; read while a drag it sent before is still
    /// being solved, that frame would not acknowledge it, and the drag
    /// would be applied twice. Returns at once when the session has closed.
    pub async fn drags_shown(&self, within: std::time::Duration) {
        let (tx, rx) = oneshot::channel();
        if self.inner.cmd_tx.send(Cmd::DragsShown(tx)).await.is_ok() {
            let _ = tokio::time::timeout(within, rx).await;
        }
    }

    /// Stops the actor; clients get a `Closed` event.
    pub async fn close(&self) {
        let _ = self.inner.cmd_tx.send(Cmd::Close).await;
    }

    /// A receiver of pose frames (latest frame wins).
    pub fn frames(&self) -> watch::Receiver<Option<Frame>> {
        self.inner.frames.clone()
    }

    /// A receiver of events (bounded; a lagging receiver loses old events).
    pub fn events(&self) -> broadcast::Receiver<Event> {
        self.inner.events.subscribe()
    }

    /// Registers a client; everyone gets `PeerJoined`.
    pub fn join(&self) -> ClientId {
        let id = self
            .inner
            .presence
            .next_client
            .fetch_add(1, Ordering::Relaxed);
        let _ = self.inner.presence.clients.fetch_add(1, Ordering::Relaxed);
        let _ = self
            .inner
            .events
            .send(Event::Peer(PeerEvent::PeerJoined { client: id }));
        self.touch();
        id
    }

    /// Unregisters a client, releasing its handles; everyone gets `PeerLeft`.
    pub fn leave(&self, client: ClientId) {
        let released = self.inner.shared.lock().grabs.release_client(client);
        if !released.is_empty() {
            let _ = self.inner.cmd_tx.try_send(Cmd::GestureEnded);
        }
        for handle in released {
            let _ = self
                .inner
                .events
                .send(Event::Peer(PeerEvent::HandleReleased { handle, client }));
        }
        let _ = self.inner.presence.clients.fetch_sub(1, Ordering::Relaxed);
        let _ = self
            .inner
            .events
            .send(Event::Peer(PeerEvent::PeerLeft { client }));
        self.touch();
    }

    /// Grabs a handle for `client` (one holder at a time).
    pub fn grab(&self, client: ClientId, h: &HandleRef) -> Result<usize, SessionError> {
        let handle = self.handle_index(h)?;
        match self.inner.shared.lock().grabs.grab(handle, client) {
            Err(_) => return Err(SessionError::HandleGrabbed { handle: h.clone() }),
            Ok(false) => return Ok(handle),
            Ok(true) => {}
        }
        let _ = self
            .inner
            .events
            .send(Event::Peer(PeerEvent::HandleGrabbed { handle, client }));
        Ok(handle)
    }

    /// Releases a handle held by `client` (a no-op if not held by it).
    pub fn release(&self, client: ClientId, h: &HandleRef) -> Result<usize, SessionError> {
        let handle = self.handle_index(h)?;
        let released = self.inner.shared.lock().grabs.release(handle, client);
        if released {
            // a full queue already holds work that ends in a settle check
            let _ = self.inner.cmd_tx.try_send(Cmd::GestureEnded);
            let _ = self
                .inner
                .events
                .send(Event::Peer(PeerEvent::HandleReleased { handle, client }));
        }
        Ok(handle)
    }
}
