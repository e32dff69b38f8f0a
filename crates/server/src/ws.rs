//! The WebSocket protocol (`GET /v1/sessions/{id}/ws`, see
//! `api/ws-protocol.md`). [`run_connection`] holds the whole logic, generic
//! over a `Sink`/`Stream` of [`WsMsg`], so it is unit-tested over channels;
//! [`upgrade`] only adapts axum's socket to it.

use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap};
use axum::response::Response;
use bytes::Bytes;
use futures_util::{Sink, SinkExt, Stream, StreamExt};
use serde::{Deserialize, Serialize};
use tokio::sync::broadcast::error::RecvError;
use tokio::time::Instant;

use super::error::ApiError;
use super::metrics::Metrics;
use super::sessions::{check_token, find, parse_json, DeltaJson};
use super::AppState;
use crate::session::{ClientId, Event, HandleRef, PeerEvent, SessionHandle, SessionInfo};

/// Close code: no token (neither `?token=` nor a first `auth` message).
pub const CLOSE_MISSING_TOKEN: u16 = 4001;
/// Close code: wrong token.
pub const CLOSE_WRONG_TOKEN: u16 = 4003;
/// Close code: the session was closed (deleted or expired).
pub const CLOSE_SESSION_CLOSED: u16 = 4004;

/// A transport-independent WebSocket message.
#[derive(Debug, Clone, PartialEq)]
pub enum WsMsg {
    /// A text (JSON) message.
    Text(String),
    /// A binary message (pose frames).
    Binary(Bytes),
    /// A close with code and reason.
    Close(u16, String),
}

/// Client → server messages (JSON, `type` tagged).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ClientMsg {
    /// Authenticate (first message, when no `?token=` was given).
    Auth {
        /// The session token.
        token: String,
    },
    /// A drag delta on a handle.
    Drag {
        /// Handle index or name.
        handle: HandleRef,
        /// The delta (`translate`, `rotate` or `quaternion`).
        #[serde(flatten)]
        delta: DeltaJson,
        /// Client sequence number (acknowledged in frames).
        seq: u64,
    },
    /// Take exclusive hold of a handle.
    Grab {
        /// Handle index or name.
        handle: HandleRef,
    },
    /// Let go of a handle.
    Release {
        /// Handle index or name.
        handle: HandleRef,
    },
    /// Replace the constraints (the CLI's constraints JSON).
    SetConstraints {
        /// The spec.
        constraints: serde_json::Value,
        /// The constraints revision the edit is based on: refused with
        /// `stale_constraints` if another edit replaced it (omitted: any).
        #[serde(default)]
        if_revision: Option<u64>,
    },
    /// Undo.
    Undo,
    /// Redo.
    Redo,
    /// Save the settled pose under `name` (replacing a pose of that name);
    /// the `state` that follows lists it in `poses`.
    SavePose {
        /// The name.
        name: String,
    },
    /// Make named pose `name` the current pose (an undo step).
    RestorePose {
        /// The name.
        name: String,
    },
    /// Rename named pose `name` to `to`.
    RenamePose {
        /// The current name.
        name: String,
        /// The new name.
        to: String,
    },
    /// Delete named pose `name`.
    DeletePose {
        /// The name.
        name: String,
    },
    /// Liveness probe; answered by `pong` with the same nonce.
    Ping {
        /// Echoed back.
        #[serde(default)]
        nonce: Option<serde_json::Value>,
    },
}

/// Server → client JSON events (`type` tagged).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMsg {
    /// The factor is ready; drags are accepted.
    Ready {
        /// Revision.
        revision: u64,
    },
    /// An error (of this client's message when `seq`/`request` is set).
    Error {
        /// Stable code (same table as HTTP).
        code: String,
        /// Message.
        message: String,
        /// The drag's seq, for drag errors.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        seq: Option<u64>,
    },
    /// A stage of the factor build started (`assembly`, `symbolic`,
    /// `numeric`, in that order; `ready` follows).
    BuildProgress {
        /// The stage.
        stage: crate::session::BuildStage,
    },
    /// Answer to `ping`.
    Pong {
        /// The ping's nonce.
        #[serde(default)]
        nonce: Option<serde_json::Value>,
    },
    /// The session state (sent on connect, after state changes, after lag).
    State {
        /// This connection's client id.
        you: ClientId,
        /// The session.
        #[serde(flatten)]
        session: serde_json::Value,
    },
    /// A handle grabbed or released, a client joined or left: the
    /// session's [`PeerEvent`] as it is (its own `type` tag).
    #[serde(untagged)]
    Peer(PeerEvent),
}

impl ServerMsg {
    fn error(e: &ApiError, seq: Option<u64>) -> Self {
        let b = e.body();
        ServerMsg::Error {
            code: b.code,
            message: b.message,
            seq,
        }
    }
    fn state(you: ClientId, info: &SessionInfo) -> Self {
        ServerMsg::State {
            you,
            session: serde_json::to_value(info).unwrap_or_default(),
        }
    }
    fn text(&self) -> WsMsg {
        WsMsg::Text(serde_json::to_string(self).unwrap_or_default())
    }
}

/// Per-connection limits.
#[derive(Clone)]
pub struct ConnConfig {
    /// Messages per second (token bucket, burst of the same size).
    pub max_messages_per_sec: u32,
    /// Time allowed for the `auth` message.
    pub auth_timeout: Duration,
    /// Where `set_constraints` resolves `{"group": …}` vertex sets (the
    /// session's mesh's asset, from the store); None: passed on as they are.
    pub groups: Option<AppState>,
}

impl std::fmt::Debug for ConnConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConnConfig")
            .field("max_messages_per_sec", &self.max_messages_per_sec)
            .field("auth_timeout", &self.auth_timeout)
            .field("groups", &self.groups.is_some())
            .finish()
    }
}

struct Bucket {
    rate: f64,
    tokens: f64,
    at: Instant,
}

impl Bucket {
    fn take(&mut self) -> bool {
        let now = Instant::now();
        self.tokens =
            (self.tokens + now.duration_since(self.at).as_secs_f64() * self.rate).min(self.rate);
        self.at = now;
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Waits for the first message to be `{"type":"auth","token":..}`; `Err`
/// carries the close to send.
async fn authenticate<St, E>(
    stream: &mut St,
    s: &SessionHandle,
    cfg: &ConnConfig,
) -> Result<(), (ApiError, u16)>
where
    St: Stream<Item = Result<WsMsg, E>> + Unpin,
{
    let first = tokio::time::timeout(cfg.auth_timeout, stream.next()).await;
    let token = match first {
        Ok(Some(Ok(WsMsg::Text(t)))) => match serde_json::from_str::<ClientMsg>(&t) {
            Ok(ClientMsg::Auth { token }) => Some(token),
            _ => None,
        },
        _ => None,
    };
    check_token(s, token.as_deref()).map_err(|e| {
        let code = if matches!(e, ApiError::MissingToken) {
            CLOSE_MISSING_TOKEN
        } else {
            CLOSE_WRONG_TOKEN
        };
        (e, code)
    })
}

/// Runs one client connection to its end. `authed` says whether the token
/// was already checked (query parameter or header); otherwise the first
/// message must be `auth`.
pub async fn run_connection<Si, St, E>(
    mut sink: Si,
    mut stream: St,
    s: SessionHandle,
    authed: bool,
    cfg: ConnConfig,
    metrics: Option<Arc<Metrics>>,
) where
    Si: Sink<WsMsg> + Unpin,
    St: Stream<Item = Result<WsMsg, E>> + Unpin,
{
    if !authed {
        if let Err((e, code)) = authenticate(&mut stream, &s, &cfg).await {
            let _ = sink.send(ServerMsg::error(&e, None).text()).await;
            let _ = sink.send(WsMsg::Close(code, e.code().into())).await;
            return;
        }
    }
    let mut events = s.events();
    let mut frames = s.frames();
    let me = s.join();
    if let Some(m) = &metrics {
        m.ws_clients.inc();
    }
    let _ = run_loop(
        &mut sink,
        &mut stream,
        &s,
        me,
        &cfg,
        &mut events,
        &mut frames,
    )
    .await;
    s.leave(me);
    if let Some(m) = &metrics {
        m.ws_clients.dec();
    }
}

type Frames = tokio::sync::watch::Receiver<Option<crate::session::Frame>>;

/// The message loop; `Err(())` when the sink failed.
async fn run_loop<Si, St, E>(
    sink: &mut Si,
    stream: &mut St,
    s: &SessionHandle,
    me: ClientId,
    cfg: &ConnConfig,
    events: &mut tokio::sync::broadcast::Receiver<Event>,
    frames: &mut Frames,
) -> Result<(), ()>
where
    Si: Sink<WsMsg> + Unpin,
    St: Stream<Item = Result<WsMsg, E>> + Unpin,
{
    send(sink, ServerMsg::state(me, &s.info()).text()).await?;
    let current = frames.borrow_and_update().clone();
    if let Some(f) = current {
        send(sink, WsMsg::Binary(f.bytes)).await?;
    }
    let rate = f64::from(cfg.max_messages_per_sec.max(1));
    let mut bucket = Bucket {
        rate,
        tokens: rate,
        at: Instant::now(),
    };
    loop {
        tokio::select! {
            msg = stream.next() => {
                let text = match msg {
                    Some(Ok(WsMsg::Text(t))) => t,
                    Some(Ok(WsMsg::Binary(_))) => {
                        let e = ApiError::InvalidJson("binary messages are not accepted".into());
                        send(sink, ServerMsg::error(&e, None).text()).await?;
                        continue;
                    }
                    _ => return Ok(()),
                };
                if !bucket.take() {
                    let e = ApiError::RateLimited(cfg.max_messages_per_sec);
                    send(sink, ServerMsg::error(&e, seq_of(&text)).text()).await?;
                    continue;
                }
                s.touch();
                if let Some(reply) = handle_message(s, me, &text, cfg.groups.as_ref()).await {
                    send(sink, reply.text()).await?;
                }
            }
            changed = frames.changed() => {
                if changed.is_err() {
                    send(sink, WsMsg::Close(CLOSE_SESSION_CLOSED, "session closed".into())).await?;
                    return Ok(());
                }
                let frame = frames.borrow_and_update().clone();
                if let Some(f) = frame {
                    send(sink, WsMsg::Binary(f.bytes)).await?;
                }
            }
            ev = events.recv() => {
                let msg = match ev {
                    Ok(Event::Closed) | Err(RecvError::Closed) => {
                        send(sink, WsMsg::Close(CLOSE_SESSION_CLOSED, "session closed".into())).await?;
                        return Ok(());
                    }
                    Ok(Event::Ready { revision }) => ServerMsg::Ready { revision },
                    Ok(Event::Error(e)) => ServerMsg::error(&ApiError::from(&*e), None),
                    Ok(Event::Peer(p)) => ServerMsg::Peer(p),
                    Ok(Event::BuildProgress { stage }) => ServerMsg::BuildProgress { stage },
                    Ok(Event::State) | Err(RecvError::Lagged(_)) => ServerMsg::state(me, &s.info()),
                };
                send(sink, msg.text()).await?;
            }
        }
    }
}

async fn send<Si: Sink<WsMsg> + Unpin>(sink: &mut Si, m: WsMsg) -> Result<(), ()> {
    sink.send(m).await.map_err(|_| ())
}

fn seq_of(text: &str) -> Option<u64> {
    serde_json::from_str::<serde_json::Value>(text)
        .ok()?
        .get("seq")?
        .as_u64()
}

/// Decodes one client message as the connection loop does (JSON →
/// [`ClientMsg`]; a drag's delta validated too), without applying it.
pub fn decode_client_msg(text: &str) -> Result<ClientMsg, ApiError> {
    let msg = parse_json::<ClientMsg>(text.as_bytes())?;
    if let ClientMsg::Drag { delta, .. } = &msg {
        let _ = delta.to_delta()?;
    }
    Ok(msg)
}

/// Applies one client message; returns the direct reply, if any.
async fn handle_message(
    s: &SessionHandle,
    me: ClientId,
    text: &str,
    groups: Option<&AppState>,
) -> Option<ServerMsg> {
    let msg = match parse_json::<ClientMsg>(text.as_bytes()) {
        Ok(m) => m,
        Err(e) => return Some(ServerMsg::error(&e, seq_of(text))),
    };
    let result: Result<Option<ServerMsg>, ApiError> = async {
        match msg {
            ClientMsg::Auth { .. } => Ok(None),
            ClientMsg::Ping { nonce } => Ok(Some(ServerMsg::Pong { nonce })),
            ClientMsg::Drag { handle, delta, seq } => {
                let d = delta.to_delta()?;
                s.drag(me, &handle, d, seq).await?;
                Ok(None)
            }
            ClientMsg::Grab { handle } => s.grab(me, &handle).map(|_| None).map_err(ApiError::from),
            ClientMsg::Release { handle } => {
                s.release(me, &handle).map(|_| None).map_err(ApiError::from)
            }
            ClientMsg::SetConstraints {
                constraints,
                if_revision,
            } => {
                let constraints = match groups {
                    Some(st) => {
                        crate::meshes::resolve_groups(st, &s.info().mesh_id, constraints).await?
                    }
                    None => constraints,
                };
                s.set_constraints(constraints, if_revision)
                    .await
                    .map(|_| None)
                    .map_err(ApiError::from)
            }
            ClientMsg::Undo => s.undo().await.map(|_| None).map_err(ApiError::from),
            ClientMsg::Redo => s.redo().await.map(|_| None).map_err(ApiError::from),
            ClientMsg::SavePose { name } => s
                .save_pose(&name)
                .await
                .map(|_| None)
                .map_err(ApiError::from),
            ClientMsg::RestorePose { name } => s
                .restore_pose(&name)
                .await
                .map(|_| None)
                .map_err(ApiError::from),
            ClientMsg::RenamePose { name, to } => s
                .rename_pose(&name, &to)
                .await
                .map(|_| None)
                .map_err(ApiError::from),
            ClientMsg::DeletePose { name } => s
                .delete_pose(&name)
                .await
                .map(|_| None)
                .map_err(ApiError::from),
        }
    }
    .await;
    result.unwrap_or_else(|e| Some(ServerMsg::error(&e, seq_of(text))))
}

/// `?token=` of the upgrade request.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WsQuery {
    /// The session token (alternative to the first `auth` message).
    pub token: Option<String>,
}

/// `GET /v1/sessions/{id}/ws`: upgrades after checking the token when one
/// is given in the query or `Authorization` header (wrong → 403 before
/// the upgrade).
pub async fn upgrade(
    State(st): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<WsQuery>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Result<Response, ApiError> {
    let header_token = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::to_owned);
    let token = q.token.or(header_token);
    // a stored, not-live session is re-opened only with its token here
    // (not with a later `auth` message)
    let s = find(&st, &id, token.as_deref()).await?;
    let authed = match token {
        Some(t) => {
            check_token(&s, Some(&t))?;
            true
        }
        None => false,
    };
    let cfg = ConnConfig {
        max_messages_per_sec: st.config.ws_max_messages_per_sec,
        auth_timeout: Duration::from_secs(10),
        groups: Some(st.clone()),
    };
    let metrics = st.metrics.clone();
    Ok(ws
        .max_message_size(st.config.ws_max_message_bytes)
        .on_upgrade(move |socket: WebSocket| async move {
            let (sink, stream) = socket.split();
            let sink =
                sink.with(|m: WsMsg| futures_util::future::ready(Ok::<_, axum::Error>(to_axum(m))));
            let stream = stream.filter_map(|m| futures_util::future::ready(from_axum(m)));
            run_connection(
                Box::pin(sink),
                Box::pin(stream),
                s,
                authed,
                cfg,
                Some(metrics),
            )
            .await;
        }))
}

fn to_axum(m: WsMsg) -> Message {
    match m {
        WsMsg::Text(t) => Message::Text(t.into()),
        WsMsg::Binary(b) => Message::Binary(b),
        WsMsg::Close(code, reason) => Message::Close(Some(CloseFrame {
            code,
            reason: reason.into(),
        })),
    }
}

fn from_axum(m: Result<Message, axum::Error>) -> Option<Result<WsMsg, axum::Error>> {
    match m {
        Ok(Message::Text(t)) => Some(Ok(WsMsg::Text(t.to_string()))),
        Ok(Message::Binary(b)) => Some(Ok(WsMsg::Binary(b))),
        Ok(Message::Close(c)) => Some(Ok(WsMsg::Close(
            c.as_ref().map_or(1005, |c| c.code),
            String::new(),
        ))),
        Ok(Message::Ping(_) | Message::Pong(_)) => None,
        Err(e) => Some(Err(e)),
    }
}

#[cfg(test)]
#[path = "ws_tests.rs"]
mod tests;
