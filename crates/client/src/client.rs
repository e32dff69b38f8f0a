//! The HTTP client bound to a server: health, metrics, meshes, and
//! creating or reopening sessions.

use dend_protocol::ws::{CreateSession, Created};
use dend_protocol::{GenerateMesh, MeshInfo, PresetList, SessionParams};

use crate::error::{check, ClientError};
use crate::session::SessionClient;

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

    /// `GET /healthz/ready`: `Ok` when the instance takes requests (its
    /// store answers, it is not draining), else the server's error.
    pub async fn ready(&self) -> Result<(), ClientError> {
        let r = self
            .http
            .get(format!("{}/healthz/ready", self.base))
            .send()
            .await?;
        let _ = check(r).await?;
        Ok(())
    }

    /// `GET /v1/presets`: the named parameter sets, the default first.
    pub async fn presets(&self) -> Result<PresetList, ClientError> {
        let r = self
            .http
            .get(format!("{}/v1/presets", self.base))
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// `GET /v1/meshes/{id}`.
    pub async fn mesh(&self, id: &str) -> Result<MeshInfo, ClientError> {
        let url = segment(&self.base, &["v1", "meshes", id])?;
        let r = self.http.get(url).send().await?;
        Ok(check(r).await?.json().await?)
    }

    /// `DELETE /v1/meshes/{id}` (refused with `mesh_in_use` while sessions
    /// edit it).
    pub async fn delete_mesh(&self, id: &str) -> Result<(), ClientError> {
        let url = segment(&self.base, &["v1", "meshes", id])?;
        let r = self.http.delete(url).send().await?;
        let _ = check(r).await?;
        Ok(())
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

    /// `POST /v1/meshes/generate`: a generated shape.
    pub async fn generate(&self, body: &GenerateMesh) -> Result<MeshInfo, ClientError> {
        let r = self
            .http
            .post(format!("{}/v1/meshes/generate", self.base))
            .json(body)
            .send()
            .await?;
        Ok(check(r).await?.json().await?)
    }

    /// An existing session, opened with its id and token (e.g. to
    /// reconnect after a server restart).
    pub fn session(&self, id: &str, token: &str) -> SessionClient {
        SessionClient::new(
            self.http.clone(),
            self.base.clone(),
            id.to_owned(),
            token.to_owned(),
        )
    }

    /// Creates a session on a mesh (`SessionParams::default()`: the
    /// default preset).
    pub async fn create_session(
        &self,
        mesh_id: &str,
        params: SessionParams,
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
        Ok(SessionClient::new(
            self.http.clone(),
            self.base.clone(),
            created.id,
            created.token,
        ))
    }
}

/// `base` with the path `parts`, each percent-encoded as one segment (a
/// mesh id or a pose name may hold spaces, `/` or `?`).
pub(crate) fn segment(base: &str, parts: &[&str]) -> Result<reqwest::Url, ClientError> {
    let mut url =
        reqwest::Url::parse(base).map_err(|e| ClientError::Protocol(format!("{base}: {e}")))?;
    url.path_segments_mut()
        .map_err(|()| ClientError::Protocol(format!("{base} cannot have a path")))?
        .pop_if_empty()
        .extend(parts);
    Ok(url)
}
