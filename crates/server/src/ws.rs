//! The WebSocket protocol (`GET /v1/sessions/{id}/ws`, see
//! `api/ws-protocol.md`). [`run_connection`] holds the whole logic, generic
//! over a `Sink`/`Stream` of [`WsMsg`], so it is unit-tested over channels;
//! [`upgrade`] only adapts axum's socket to it.

use std::sync::Arc;
use std::time::Duration;

use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::HeaderMap;
use axum::response::Response;
use bytes::Bytes;
use futures_util::{Sink, SinkExt, Stream, StreamExt};
use serde::Deserialize;
use tokio::sync::broadcast::error::RecvError;
use tokio::time::Instant;

use crate::auth::{bearer, check_token};
use crate::error::{ApiError, Path, Query};
use crate::metrics::Metrics;
use crate::session::{wire_stage, Event, SessionHandle};
use crate::sessions::{find, parse_json, to_delta};
use crate::state::AppState;
pub use dend_protocol::ws::{ClientId, ServerMsg, SessionInfo, StreamOptions};

/// A client message as the server reads it: the protocol's, with the
/// constraint set as raw JSON (a set that does not parse is answered
/// `invalid_constraints` by the session, not `invalid_json`).
pub type ClientMsg = dend_protocol::ws::ClientMsgOf<serde_json::Value>;
use dend_protocol::FrameEncoding;
use flow::Flow;

#[path = "ws_flow.rs"]
mod flow;

/// Close code: no token (neither `?token=` nor a first `auth` message).
pub const CLOSE_MISSING_TOKEN: u16 = 4001;
/// Close code: wrong token.
pub const CLOSE_WRONG_TOKEN: u16 = 4003;
/// Close code: the session was closed (deleted or expired).
pub const CLOSE_SESSION_CLOSED: u16 = 4004;
/// Close code: the session moved to another instance (a rolling restart,
/// a rebalancing): reconnect at once, through the load balancer.
pub const CLOSE_RECONNECT: u16 = 4012;

/// The close of a connection whose session ended here: moved elsewhere
/// (reconnect at once) or closed.
fn session_end(s: &SessionHandle) -> WsMsg {
    if s.is_moving() {
        WsMsg::Close(CLOSE_RECONNECT, "session moved: reconnect".into())
    } else {
        WsMsg::Close(CLOSE_SESSION_CLOSED, "session closed".into())
    }
}

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

/// The server's messages built from its own types.
trait ServerMsgExt {
    /// The `error` event of an API error (`seq`: the failed drag's).
    fn error(e: &ApiError, seq: Option<u64>) -> ServerMsg {
        let b = e.body();
        ServerMsg::Error {
            code: b.code,
            message: b.message,
            seq,
        }
    }
    /// The `state` event for client `you`.
    fn state(you: ClientId, info: SessionInfo) -> ServerMsg {
        ServerMsg::State { you, session: info }
    }
    /// The message as a text frame.
    fn text(&self) -> WsMsg;
}

impl ServerMsgExt for ServerMsg {
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
    /// How frames are streamed (flow-control window, encoding).
    pub stream: StreamOptions,
}

impl std::fmt::Debug for ConnConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConnConfig")
            .field("max_messages_per_sec", &self.max_messages_per_sec)
            .field("auth_timeout", &self.auth_timeout)
            .field("groups", &self.groups.is_some())
            .field("stream", &self.stream)
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
            let _ = sink.send(WsMsg::Close(code, e.code().to_string())).await;
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
    send(sink, ServerMsg::state(me, s.info()).text()).await?;
    let mut flow = Flow::new(cfg.stream);
    // the first frame tells a reconnecting client which of its drags to
    // send again: it waits for the drags the session holds to be shown
    s.drags_shown(crate::session::DRAGS_SHOWN_WAIT).await;
    let current = frames.borrow_and_update().clone();
    if let Some(f) = current {
        send_frame(sink, &mut flow, &f).await?;
    }
    let rate = f64::from(cfg.max_messages_per_sec.max(1));
    let mut bucket = Bucket {
        rate,
        tokens: rate,
        at: Instant::now(),
    };
    // the latest frame seen and not sent (the window or a rate cap held
    // it back); a newer one replaces it
    let mut pending: Option<crate::session::Frame> = None;
    loop {
        // the latest frame goes out once the window and the rate caps let
        // it (after an ack, a new frame, or the end of a rate interval)
        let now = Instant::now();
        if let Some(f) = pending.take_if(|f| flow.open(now, &f.header)) {
            send_frame(sink, &mut flow, &f).await?;
            continue;
        }
        let rate_wait = pending
            .as_ref()
            .filter(|_| flow.window_open())
            .and_then(|f| flow.rate_wait(now, &f.header));
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
                let parsed = parse_json::<ClientMsg>(text.as_bytes());
                if let Ok(ClientMsg::Ack { revision }) = parsed {
                    // not rate limited: a client acks at most the frames it got
                    flow.ack(revision);
                    continue;
                }
                if !bucket.take() {
                    let e = ApiError::RateLimited(cfg.max_messages_per_sec);
                    send(sink, ServerMsg::error(&e, seq_of(&text)).text()).await?;
                    continue;
                }
                s.touch();
                let reply = match parsed {
                    Ok(msg) => handle_message(s, me, msg, cfg.groups.as_ref()).await,
                    Err(e) => Err(e),
                };
                match reply {
                    Ok(Some(reply)) => send(sink, reply.text()).await?,
                    Ok(None) => {}
                    // the session left for another instance between this
                    // message and the close: not a refusal, a reconnect
                    // (the client sends what was not acknowledged again)
                    Err(ApiError::SessionClosed) if s.is_moving() => {
                        send(sink, session_end(s)).await?;
                        return Ok(());
                    }
                    Err(e) => send(sink, ServerMsg::error(&e, seq_of(&text)).text()).await?,
                }
            }
            // while the window is full the latest frame waits in the
            // channel (later ones replace it) until an ack opens it
            changed = frames.changed(), if flow.window_open() => {
                if changed.is_err() {
                    send(sink, session_end(s)).await?;
                    return Ok(());
                }
                // sent at the top of the loop, now or when the rate caps
                // let it; a frame answering a drag replaces a refinement
                // held back by `refine_fps` at once
                pending = frames.borrow_and_update().clone();
            }
            // a frame held back by a rate cap: the end of its interval
            () = crate::session::sleep_until_or_never(rate_wait), if rate_wait.is_some() => {}
            ev = events.recv() => {
                let msg = match ev {
                    Ok(Event::Closed) | Err(RecvError::Closed) => {
                        send(sink, session_end(s)).await?;
                        return Ok(());
                    }
                    Ok(Event::Ready { revision }) => ServerMsg::Ready { revision },
                    Ok(Event::Error(e)) => ServerMsg::error(&ApiError::from(&*e), None),
                    Ok(Event::Peer(p)) => ServerMsg::Peer(p),
                    Ok(Event::BuildProgress { stage }) => ServerMsg::BuildProgress { stage: wire_stage(stage) },
                    Ok(Event::State) | Err(RecvError::Lagged(_)) => ServerMsg::state(me, s.info()),
                };
                send(sink, msg.text()).await?;
            }
        }
    }
}

/// Sends frame `f` as this connection wants it.
async fn send_frame<Si: Sink<WsMsg> + Unpin>(
    sink: &mut Si,
    flow: &mut Flow,
    f: &crate::session::Frame,
) -> Result<(), ()> {
    match flow.take(f) {
        Some(bytes) => send(sink, WsMsg::Binary(bytes)).await,
        None => Ok(()),
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
        let _ = to_delta(delta)?;
    }
    Ok(msg)
}

/// Applies one client message; returns the direct reply, if any.
async fn handle_message(
    s: &SessionHandle,
    me: ClientId,
    msg: ClientMsg,
    groups: Option<&AppState>,
) -> Result<Option<ServerMsg>, ApiError> {
    match msg {
        ClientMsg::Auth { .. } => Ok(None),
        ClientMsg::Ping { nonce } => Ok(Some(ServerMsg::Pong { nonce })),
        ClientMsg::Drag { handle, delta, seq } => {
            let d = to_delta(&delta)?;
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
        ClientMsg::Ack { .. } => Ok(None),
        ClientMsg::Undo => s.undo().await.map(|_| None).map_err(ApiError::from),
        ClientMsg::Redo => s.redo().await.map(|_| None).map_err(ApiError::from),
        ClientMsg::SavePose { name, replace } => s
            .save_pose(&name, replace)
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

/// The query of the upgrade request: `?token=` and the stream options
/// (`window`, `encoding`, `max_fps`, `refine_fps`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WsQuery {
    /// The session token (alternative to the first `auth` message).
    pub token: Option<String>,
    /// Flow-control window ([`StreamOptions::window`]).
    pub window: Option<u32>,
    /// Frame encoding ([`StreamOptions::encoding`]).
    pub encoding: Option<FrameEncoding>,
    /// Frame rate cap ([`StreamOptions::max_fps`]).
    pub max_fps: Option<u32>,
    /// Refinement frame rate cap ([`StreamOptions::refine_fps`]).
    pub refine_fps: Option<u32>,
}

/// `GET /v1/sessions/{id}/ws`: upgrades after checking the token when one
/// is given in the query or `Authorization` header (wrong → 403 before
/// the upgrade).
pub async fn upgrade(
    State(st): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<WsQuery>,
    headers: HeaderMap,
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let stream = StreamOptions {
        window: q.window,
        encoding: q.encoding,
        max_fps: q.max_fps,
        refine_fps: q.refine_fps,
    };
    stream.validate().map_err(ApiError::InvalidParams)?;
    let token = q.token.or_else(|| bearer(&headers).map(str::to_owned));
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
    // not an upgrade request: a JSON 400 `invalid_upgrade` (after the
    // session and token checks, as on every session route)
    let ws = ws?;
    let cfg = ConnConfig {
        max_messages_per_sec: st.config.ws_max_messages_per_sec,
        auth_timeout: Duration::from_secs(10),
        groups: Some(st.clone()),
        stream,
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
