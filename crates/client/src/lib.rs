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
//! # Ok(()) }
//! ```

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio_tungstenite::tungstenite::Message;

use dend_protocol::{decode_frame, FrameError, FrameHeader};

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
        /// Error code.
        code: String,
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

/// A mesh as the API describes it (the server's own type).
pub use dend_protocol::MeshInfo;
/// A pose as JSON (the server's own type).
pub use dend_protocol::PoseJson as Pose;

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
    let body: Value = r.json().await.unwrap_or(Value::Null);
    Err(ClientError::Api {
        status,
        code: body["code"].as_str().unwrap_or("").to_owned(),
        message: body["message"].as_str().unwrap_or("").to_owned(),
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
            .json(&json!({"positions": positions, "triangles": triangles}))
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
            .json(&json!({"mesh_id": mesh_id, "params": params}))
            .send()
            .await?;
        let v: Value = check(r).await?.json().await?;
        Ok(SessionClient {
            http: self.http.clone(),
            base: self.base.clone(),
            id: v["id"].as_str().unwrap_or("").to_owned(),
            token: v["token"].as_str().unwrap_or("").to_owned(),
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

    async fn post(
        &self,
        tail: &str,
        body: Option<Value>,
    ) -> Result<reqwest::Response, ClientError> {
        let mut rq = self.http.post(self.url(tail)).bearer_auth(&self.token);
        if let Some(b) = body {
            rq = rq.json(&b);
        }
        check(rq.send().await?).await
    }

    /// `GET /v1/sessions/{id}`.
    pub async fn info(&self) -> Result<Value, ClientError> {
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
        let body: Value = check(r).await?.json().await?;
        body["constraints_revision"]
            .as_u64()
            .ok_or_else(|| ClientError::Protocol(format!("no constraints_revision in {body}")))
    }

    /// Polls until the state is `ready` (or `failed` → error).
    pub async fn wait_ready(&self, timeout: Duration) -> Result<(), ClientError> {
        let end = tokio::time::Instant::now() + timeout;
        // polls from 1 ms, doubling to 20 ms: a 10k factor is ready in
        // tens of milliseconds, a large one in seconds
        let mut pause = Duration::from_millis(1);
        loop {
            let v = self.info().await?;
            match v["state"].as_str() {
                Some("ready") => return Ok(()),
                Some("failed") => return Err(ClientError::Protocol("factor build failed".into())),
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

    /// HTTP drag: delta + solve, returns the pose.
    pub async fn drag(
        &self,
        handle: Value,
        delta: Value,
        max_iters: Option<usize>,
    ) -> Result<Pose, ClientError> {
        let mut body = delta;
        body["handle"] = handle;
        if let Some(m) = max_iters {
            body["max_iters"] = json!(m);
        }
        Ok(self.post("/drag", Some(body)).await?.json().await?)
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
        Ok(self.post("/undo", None).await?.json().await?)
    }

    /// Redo.
    pub async fn redo(&self) -> Result<Pose, ClientError> {
        Ok(self.post("/redo", None).await?.json().await?)
    }

    /// Reset.
    pub async fn reset(&self) -> Result<Pose, ClientError> {
        Ok(self.post("/reset", None).await?.json().await?)
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

    /// Opens the WebSocket (token in the query).
    pub async fn connect(&self) -> Result<WsClient, ClientError> {
        let url = format!(
            "{}/ws?token={}",
            self.url("").replacen("http", "ws", 1),
            self.token
        );
        let (ws, _) = tokio_tungstenite::connect_async(url)
            .await
            .map_err(Box::new)?;
        Ok(WsClient { ws })
    }
}

/// A message from the server.
#[derive(Debug, Clone)]
pub enum WsEvent {
    /// A pose frame.
    Frame(FrameHeader, Vec<[f32; 3]>),
    /// A JSON event.
    Event(Value),
    /// The server closed (code).
    Closed(Option<u16>),
}

/// A WebSocket connection to a session.
pub struct WsClient {
    ws: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
}

impl WsClient {
    /// Sends a JSON message.
    pub async fn send(&mut self, v: &Value) -> Result<(), ClientError> {
        self.ws
            .send(Message::Text(v.to_string().into()))
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
        let mut m = json!({"type": "drag", "handle": handle, "translate": translate, "seq": seq});
        if let Some(q) = quaternion {
            m["quaternion"] = json!(q);
        }
        self.send(&m).await
    }

    /// The next frame or event.
    pub async fn next(&mut self) -> Result<WsEvent, ClientError> {
        loop {
            match self.ws.next().await {
                None => return Ok(WsEvent::Closed(None)),
                Some(Err(e)) => return Err(Box::new(e).into()),
                Some(Ok(Message::Binary(b))) => {
                    let (h, v) = decode_frame(&b)?;
                    return Ok(WsEvent::Frame(h, v));
                }
                Some(Ok(Message::Text(t))) => {
                    return serde_json::from_str(&t)
                        .map(WsEvent::Event)
                        .map_err(|e| ClientError::Protocol(e.to_string()));
                }
                Some(Ok(Message::Close(c))) => {
                    return Ok(WsEvent::Closed(c.map(|c| c.code.into())))
                }
                Some(Ok(_)) => continue,
            }
        }
    }

    /// Skips to the next event of type `ty` (frames and other events dropped).
    pub async fn event(&mut self, ty: &str) -> Result<Value, ClientError> {
        loop {
            match self.next().await? {
                WsEvent::Event(v) if v["type"] == ty => return Ok(v),
                WsEvent::Closed(c) => {
                    return Err(ClientError::Protocol(format!(
                        "closed ({c:?}) before `{ty}`"
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
                WsEvent::Event(v) if v["type"] == "error" => {
                    return Err(ClientError::Protocol(format!("error event: {v}")));
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
