//! A session opened with its token: its HTTP routes, and opening its
//! WebSocket.

use std::time::Duration;

use dend_protocol::ws::{
    DeltaJson, DragRequest, HandleRef, SessionInfo, SessionState, StreamOptions,
};
use dend_protocol::{ConstraintsAccepted, ConstraintsSpec, Curvature, FrameEncoding};

use crate::error::{check, ClientError};
use crate::socket::WsClient;
use dend_protocol::PoseJson as Pose;

/// A session opened with its token.
#[derive(Debug, Clone)]
pub struct SessionClient {
    pub(crate) http: reqwest::Client,
    pub(crate) base: String,
    /// Session id.
    pub id: String,
    /// Access token.
    pub token: String,
}

impl SessionClient {
    pub(crate) fn new(http: reqwest::Client, base: String, id: String, token: String) -> Self {
        SessionClient {
            http,
            base,
            id,
            token,
        }
    }

    fn url(&self, tail: &str) -> String {
        format!("{}/v1/sessions/{}{}", self.base, self.id, tail)
    }

    pub(crate) async fn post<B: serde::Serialize>(
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
    pub async fn set_constraints(
        &self,
        spec: &ConstraintsSpec,
    ) -> Result<ConstraintsAccepted, ClientError> {
        let r = self
            .http
            .put(self.url("/constraints"))
            .bearer_auth(&self.token)
            .json(spec)
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// Sets constraints only if the session's constraints revision is still
    /// `revision` (`If-Match`); returns the new revision. Another client's
    /// edit in between gives `ClientError::Api` with `stale_constraints`.
    pub async fn set_constraints_if(
        &self,
        spec: &ConstraintsSpec,
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
        let body: ConstraintsAccepted = check(r).await?.json().await?;
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

    /// `GET /v1/sessions/{id}/curvature`: per-vertex curvatures of the
    /// current pose.
    pub async fn curvature(&self) -> Result<Curvature, ClientError> {
        let r = self
            .http
            .get(self.url("/curvature"))
            .bearer_auth(&self.token)
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
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
        WsClient::open(url, opts.window.is_some()).await
    }
}
