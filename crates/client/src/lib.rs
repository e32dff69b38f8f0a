//! A small Rust client of the dend server (HTTP + WebSocket), used by the
//! end-to-end tests and `dend loadtest`, usable by tool backends.
//!
//! ```no_run
//! # async fn demo() -> Result<(), dend_client::ClientError> {
//! use dend::client::Client;
//! let c = Client::new("http://127.0.0.1:8080");
//! let mesh = c.upload_json(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]]).await?;
//! let s = c.create_session(&mesh.id, serde_json::json!({})).await?;
//! let mut ws = s.connect().await?;
//! ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
//! let (header, positions) = ws.frame_acking(1, false).await?;
//! # let _ = (header, positions);
//! # Ok(()) }
//! ```

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;

use dend_protocol::ws::{
    ClientMsg, CreateSession, Created, DeltaJson, DragRequest, HandleRef, ServerMsg, SessionInfo,
    SessionState, StreamOptions,
};
use dend_protocol::{DecodedFrame, FrameDecoder, FrameError, FrameHeader};

/// Client errors.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Transport failure (reqwest's message, its causes as the `source`
    /// chain: each said once).
    #[error(transparent)]
    Http(#[from] reqwest::Error),
    /// The server answered with an error body.
    #[error("{status}: {code}: {message}")]
    Api {
        /// HTTP status.
        status: u16,
        /// Error code (a code this client does not know is
        /// [`ErrorCode::Other`]).
        code: ErrorCode,
        /// Message.
        message: String,
    },
    /// WebSocket failure (tungstenite's message and causes, each once).
    #[error(transparent)]
    Ws(#[from] Box<tokio_tungstenite::tungstenite::Error>),
    /// A bad frame (its message here, not as a `source`: chained reports
    /// would print it twice).
    #[error("frame: {0}")]
    Frame(FrameError),
    /// Unexpected message or closed connection.
    #[error("protocol: {0}")]
    Protocol(String),
}

impl From<FrameError> for ClientError {
    fn from(e: FrameError) -> Self {
        ClientError::Frame(e)
    }
}

/// The wire types (messages, session info, stream options).
pub use dend_protocol::ws;
/// How version 3 frames store positions.
pub use dend_protocol::FrameEncoding;
/// A mesh as the API describes it (the server's own type).
pub use dend_protocol::MeshInfo;
/// A pose as JSON (the server's own type).
pub use dend_protocol::PoseJson as Pose;
/// The error body of a failed request and its stable codes (the server's
/// own types).
pub use dend_protocol::{ErrorBody, ErrorCode};

/// `POST /v1/meshes` JSON body.
#[derive(serde::Serialize)]
struct UploadJson<'a> {
    positions: &'a [[f64; 3]],
    triangles: &'a [[u32; 3]],
}

/// An HTTP client bound to a server base URL (`http://host:port`).
#[derive(Debug, Clone)]
pub struct Client {
    http: reqwest::Client,
    base: String,
}

async fn check(r: reqwest::Response) -> Result<reqwest::Response, ClientError> {
    if r.status().is_success() {
        return Ok(r);
    }
    let status = r.status().as_u16();
    let body: ErrorBody = r.json().await.unwrap_or_default();
    Err(ClientError::Api {
        status,
        code: body.code,
        message: body.message,
    })
}

impl Client {
    /// A client of the server at `base` (e.g. `http://127.0.0.1:8080`).
    pub fn new(base: &str) -> Self {
        Client {
            http: reqwest::Client::new(),
            base: base.trim_end_matches('/').to_owned(),
        }
    }

    /// The base URL.
    pub fn base(&self) -> &str {
        &self.base
    }

    /// `GET /healthz`.
    pub async fn healthz(&self) -> Result<(), ClientError> {
        let _ = check(
            self.http
                .get(format!("{}/healthz", self.base))
                .send()
                .await?,
        )
        .await?;
        Ok(())
    }

    /// The value of the sample `name` in `GET /metrics` (the full name,
    /// e.g. `dend_factor_cache_bytes` or `dend_solve_seconds_count`), or
    /// `None` when the server does not export it.
    pub async fn metric(&self, name: &str) -> Result<Option<f64>, ClientError> {
        let text = check(
            self.http
                .get(format!("{}/metrics", self.base))
                .send()
                .await?,
        )
        .await?
        .text()
        .await?;
        Ok(text
            .lines()
            .filter(|l| !l.starts_with('#'))
            .find_map(|l| match l.split_once(' ') {
                Some((k, v)) if k == name => v.trim().parse().ok(),
                _ => None,
            }))
    }

    /// Uploads a mesh as JSON.
    pub async fn upload_json(
        &self,
        positions: &[[f64; 3]],
        triangles: &[[u32; 3]],
    ) -> Result<MeshInfo, ClientError> {
        let r = self
            .http
            .post(format!("{}/v1/meshes", self.base))
            .json(&UploadJson {
                positions,
                triangles,
            })
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// Uploads a mesh file (`format`: obj, off, ply, stl, gltf, glb).
    pub async fn upload_file(&self, bytes: Vec<u8>, format: &str) -> Result<MeshInfo, ClientError> {
        let r = self
            .http
            .post(format!("{}/v1/meshes?format={format}", self.base))
            .header("content-type", "application/octet-stream")
            .body(bytes)
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// Generates a mesh (`{"shape": .., ...}`).
    pub async fn generate(&self, body: Value) -> Result<MeshInfo, ClientError> {
        let r = self
            .http
            .post(format!("{}/v1/meshes/generate", self.base))
            .json(&body)
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// An existing session, opened with its id and token (e.g. to
    /// reconnect after a server restart).
    pub fn session(&self, id: &str, token: &str) -> SessionClient {
        SessionClient {
            http: self.http.clone(),
            base: self.base.clone(),
            id: id.to_owned(),
            token: token.to_owned(),
        }
    }

    /// Creates a session on a mesh.
    pub async fn create_session(
        &self,
        mesh_id: &str,
        params: Value,
    ) -> Result<SessionClient, ClientError> {
        let r = self
            .http
            .post(format!("{}/v1/sessions", self.base))
            .json(&CreateSession {
                mesh_id: mesh_id.to_owned(),
                params,
            })
            .send()
            .await?;
        let created: Created = check(r).await?.json().await?;
        Ok(SessionClient {
            http: self.http.clone(),
            base: self.base.clone(),
            id: created.id,
            token: created.token,
        })
    }
}

/// A session opened with its token.
#[derive(Debug, Clone)]
pub struct SessionClient {
    http: reqwest::Client,
    base: String,
    /// Session id.
    pub id: String,
    /// Access token.
    pub token: String,
}

impl SessionClient {
    fn url(&self, tail: &str) -> String {
        format!("{}/v1/sessions/{}{}", self.base, self.id, tail)
    }

    async fn post<B: serde::Serialize>(
        &self,
        tail: &str,
        body: Option<&B>,
    ) -> Result<reqwest::Response, ClientError> {
        let mut rq = self.http.post(self.url(tail)).bearer_auth(&self.token);
        if let Some(b) = body {
            rq = rq.json(b);
        }
        check(rq.send().await?).await
    }

    /// `GET /v1/sessions/{id}`.
    pub async fn info(&self) -> Result<SessionInfo, ClientError> {
        let r = self
            .http
            .get(self.url(""))
            .bearer_auth(&self.token)
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// Sets constraints (202; the factor builds in the background).
    pub async fn set_constraints(&self, spec: &Value) -> Result<(), ClientError> {
        let r = self
            .http
            .put(self.url("/constraints"))
            .bearer_auth(&self.token)
            .json(spec)
            .send()
            .await?;
        let _ = check(r).await?;
        Ok(())
    }

    /// Sets constraints only if the session's constraints revision is still
    /// `revision` (`If-Match`); returns the new revision. Another client's
    /// edit in between gives `ClientError::Api` with `stale_constraints`.
    pub async fn set_constraints_if(
        &self,
        spec: &Value,
        revision: u64,
    ) -> Result<u64, ClientError> {
        let r = self
            .http
            .put(self.url("/constraints"))
            .bearer_auth(&self.token)
            .header("if-match", format!("\"{revision}\""))
            .json(spec)
            .send()
            .await?;
        #[derive(serde::Deserialize)]
        struct Accepted {
            constraints_revision: u64,
        }
        let body: Accepted = check(r).await?.json().await?;
        Ok(body.constraints_revision)
    }

    /// Polls until the state is `ready` (or `failed` → error).
    pub async fn wait_ready(&self, timeout: Duration) -> Result<(), ClientError> {
        let end = tokio::time::Instant::now() + timeout;
        // polls from 1 ms, doubling to 20 ms: a 10k factor is ready in
        // tens of milliseconds, a large one in seconds
        let mut pause = Duration::from_millis(1);
        loop {
            match self.info().await?.state {
                SessionState::Ready => return Ok(()),
                SessionState::Failed => {
                    return Err(ClientError::Protocol("factor build failed".into()))
                }
                _ if tokio::time::Instant::now() > end => {
                    return Err(ClientError::Protocol("not ready in time".into()))
                }
                _ => {
                    tokio::time::sleep(pause).await;
                    pause = (pause * 2).min(Duration::from_millis(20));
                }
            }
        }
    }

    /// HTTP drag: delta + solve (at most `max_iters` iterations; default
    /// the session's), returns the pose.
    pub async fn drag(
        &self,
        handle: impl Into<HandleRef>,
        delta: DeltaJson,
        max_iters: Option<usize>,
    ) -> Result<Pose, ClientError> {
        let body = DragRequest {
            handle: handle.into(),
            delta,
            max_iters,
        };
        Ok(self.post("/drag", Some(&body)).await?.json().await?)
    }

    /// `GET pose` as JSON.
    pub async fn pose(&self) -> Result<Pose, ClientError> {
        let r = self
            .http
            .get(self.url("/pose"))
            .bearer_auth(&self.token)
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// `GET pose` as f32 binary.
    pub async fn pose_f32(&self) -> Result<Vec<[f32; 3]>, ClientError> {
        let r = self
            .http
            .get(self.url("/pose"))
            .bearer_auth(&self.token)
            .header("accept", "application/octet-stream")
            .send()
            .await?;
        let b = check(r).await?.bytes().await?;
        Ok(b.chunks_exact(12)
            .map(|c| {
                let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
                [f(0), f(4), f(8)]
            })
            .collect())
    }

    /// Export as a mesh file (`obj`, `off`, `ply`, `stl`).
    pub async fn export(&self, format: &str) -> Result<Vec<u8>, ClientError> {
        let r = self
            .http
            .get(self.url(&format!("/export?format={format}")))
            .bearer_auth(&self.token)
            .send()
            .await?;
        Ok(check(r).await?.bytes().await?.to_vec())
    }

    /// Undo.
    pub async fn undo(&self) -> Result<Pose, ClientError> {
        Ok(self.post::<()>("/undo", None).await?.json().await?)
    }

    /// Redo.
    pub async fn redo(&self) -> Result<Pose, ClientError> {
        Ok(self.post::<()>("/redo", None).await?.json().await?)
    }

    /// Reset.
    pub async fn reset(&self) -> Result<Pose, ClientError> {
        Ok(self.post::<()>("/reset", None).await?.json().await?)
    }

    /// Delete the session.
    pub async fn delete(&self) -> Result<(), ClientError> {
        let r = self
            .http
            .delete(self.url(""))
            .bearer_auth(&self.token)
            .send()
            .await?;
        let _ = check(r).await?;
        Ok(())
    }

    /// Opens the WebSocket with flow control (one frame in flight, each
    /// acknowledged when the next message is asked for) and full-precision
    /// (`f32`) version 3 frames.
    pub async fn connect(&self) -> Result<WsClient, ClientError> {
        self.connect_with(StreamOptions::flow(1, FrameEncoding::F32))
            .await
    }

    /// Opens the WebSocket (token in the query) with these stream options;
    /// `StreamOptions::default()` is a version 2 client (no flow control,
    /// version 2 frames).
    pub async fn connect_with(&self, opts: StreamOptions) -> Result<WsClient, ClientError> {
        let mut url = format!(
            "{}/ws?token={}",
            self.url("").replacen("http", "ws", 1),
            self.token
        );
        let q = opts.to_query();
        if !q.is_empty() {
            url = format!("{url}&{q}");
        }
        // TCP_NODELAY: an ack and the next drag go out at once instead of
        // waiting for the server's delayed ACK (Nagle's algorithm)
        let (ws, _) = tokio_tungstenite::connect_async_with_config(url, None, true)
            .await
            .map_err(Box::new)?;
        Ok(WsClient {
            ws,
            flow: opts.window.is_some(),
            to_ack: None,
            bytes: 0,
            decoder: FrameDecoder::new(),
        })
    }
}

/// A message from the server.
#[derive(Debug, Clone)]
pub enum WsEvent {
    /// A pose frame.
    Frame(FrameHeader, Vec<[f32; 3]>),
    /// A JSON event.
    Event(ServerMsg),
    /// The server closed (code).
    Closed(Option<u16>),
}

/// A WebSocket connection to a session.
pub struct WsClient {
    ws: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    /// Whether the connection declared a flow-control window (frames are
    /// acknowledged).
    flow: bool,
    /// The revision of the last frame handed to the caller, acknowledged
    /// when the caller asks for the next message (it has taken the frame).
    to_ack: Option<u64>,
    /// Bytes of the binary frames received.
    bytes: u64,
    /// Holds the last `delta` frame, which the next one's changes apply to.
    decoder: FrameDecoder,
}

impl std::fmt::Debug for WsClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WsClient")
            .field("flow", &self.flow)
            .field("bytes", &self.bytes)
            .finish_non_exhaustive()
    }
}

impl WsClient {
    /// Sends a message.
    pub async fn send(&mut self, m: &ClientMsg) -> Result<(), ClientError> {
        let text = serde_json::to_string(m).map_err(|e| ClientError::Protocol(e.to_string()))?;
        self.ws
            .send(Message::Text(text.into()))
            .await
            .map_err(Box::new)?;
        Ok(())
    }

    /// Sends a drag delta (translation; rotation as quaternion `[x,y,z,w]`).
    pub async fn drag(
        &mut self,
        handle: usize,
        translate: [f64; 3],
        quaternion: Option<[f64; 4]>,
        seq: u64,
    ) -> Result<(), ClientError> {
        self.send(&ClientMsg::Drag {
            handle: HandleRef::Index(handle),
            delta: DeltaJson::new(translate, quaternion),
            seq,
        })
        .await
    }

    /// Bytes of pose frames received so far.
    pub fn frame_bytes(&self) -> u64 {
        self.bytes
    }

    /// Acknowledges the last frame handed out, if not yet done (also done
    /// by [`WsClient::next`]: call it when a frame is taken before asking
    /// for the next message).
    pub async fn ack(&mut self) -> Result<(), ClientError> {
        // cleared once sent: a call cancelled mid-send acks again later
        if let Some(revision) = self.to_ack {
            self.send(&ClientMsg::Ack { revision }).await?;
            self.to_ack = None;
        }
        Ok(())
    }

    /// The next frame (with its box and encoding) or event. Asking for it
    /// acknowledges the frame handed out before.
    pub async fn next_full(&mut self) -> Result<WsFull, ClientError> {
        self.ack().await?;
        loop {
            match self.ws.next().await {
                None => return Ok(WsFull::Closed(None)),
                Some(Err(e)) => return Err(Box::new(e).into()),
                Some(Ok(Message::Binary(b))) => {
                    self.bytes += b.len() as u64;
                    let f = self.decoder.decode(&b)?;
                    if self.flow {
                        self.to_ack = Some(f.header.revision);
                    }
                    return Ok(WsFull::Frame(f));
                }
                Some(Ok(Message::Text(t))) => {
                    return serde_json::from_str(&t)
                        .map(WsFull::Event)
                        .map_err(|e| ClientError::Protocol(format!("{e}: {t}")));
                }
                Some(Ok(Message::Close(c))) => return Ok(WsFull::Closed(c.map(|c| c.code.into()))),
                Some(Ok(_)) => continue,
            }
        }
    }

    /// The next frame or event. Asking for it acknowledges the frame
    /// handed out before.
    pub async fn next(&mut self) -> Result<WsEvent, ClientError> {
        Ok(match self.next_full().await? {
            WsFull::Frame(f) => WsEvent::Frame(f.header, f.positions),
            WsFull::Event(e) => WsEvent::Event(e),
            WsFull::Closed(c) => WsEvent::Closed(c),
        })
    }

    /// Skips to the next event of kind `kind` (its `type`: `state`,
    /// `error`, `ready`, …; frames and other events dropped).
    pub async fn event(&mut self, kind: &str) -> Result<ServerMsg, ClientError> {
        loop {
            match self.next().await? {
                WsEvent::Event(m) if m.kind() == kind => return Ok(m),
                WsEvent::Closed(c) => {
                    return Err(ClientError::Protocol(format!(
                        "closed ({c:?}) before `{kind}`"
                    )))
                }
                _ => {}
            }
        }
    }

    /// Reads until a frame acknowledges `seq` (and is converged, if asked).
    pub async fn frame_acking(
        &mut self,
        seq: u64,
        converged: bool,
    ) -> Result<(FrameHeader, Vec<[f32; 3]>), ClientError> {
        loop {
            match self.next().await? {
                WsEvent::Frame(h, v) if h.ack_seq >= seq && (h.converged || !converged) => {
                    return Ok((h, v))
                }
                WsEvent::Event(e @ ServerMsg::Error { .. }) => {
                    return Err(ClientError::Protocol(format!("error event: {e:?}")));
                }
                WsEvent::Closed(c) => return Err(ClientError::Protocol(format!("closed ({c:?})"))),
                _ => {}
            }
        }
    }

    /// Closes the connection.
    pub async fn close(mut self) -> Result<(), ClientError> {
        self.ws.close(None).await.map_err(Box::new)?;
        Ok(())
    }
}

/// A message from the server, frames with their box and encoding.
#[derive(Debug, Clone)]
pub enum WsFull {
    /// A pose frame.
    Frame(DecodedFrame),
    /// A JSON event.
    Event(ServerMsg),
    /// The server closed (code).
    Closed(Option<u16>),
}
