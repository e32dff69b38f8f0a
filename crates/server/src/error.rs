//! The server's one error type, its one code → status table and its one
//! `IntoResponse`: every failure is JSON `{code, message}`. Client mistakes
//! carry their message; internal failures a generic one (details logged).
//!
//! axum's own extractor rejections (query string, path parameters, JSON
//! body and its content type, WebSocket upgrade headers, a method the route
//! does not serve) are mapped here too: handlers extract through
//! [`Query`] and [`Path`] (axum's extractors with an [`ApiError`]
//! rejection) and take JSON bodies as `Result<Json<T>, JsonRejection>`
//! (mapped by `?`), so no plain-text rejection reaches a client.

use axum::extract::rejection::{BytesRejection, JsonRejection, PathRejection, QueryRejection};
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::FromRequestParts;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;

use crate::session::SessionError;
use crate::store::StoreError;
use dend::deform::DeformError;

/// Every error the HTTP API and the WebSocket protocol report.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// The body is not valid JSON or does not match the expected shape.
    #[error("invalid JSON: {0}")]
    InvalidJson(String),
    /// A JSON body sent without `Content-Type: application/json`.
    #[error("{0}")]
    UnsupportedMediaType(String),
    /// A query string that does not parse or has unknown parameters.
    #[error("invalid query: {0}")]
    InvalidQuery(String),
    /// A path parameter that does not parse (e.g. not UTF-8).
    #[error("invalid path: {0}")]
    InvalidPath(String),
    /// A request to the WebSocket route that is not a WebSocket upgrade.
    #[error("not a WebSocket upgrade: {0}")]
    InvalidUpgrade(String),
    /// The route exists but does not serve this method.
    #[error("method {0} is not allowed on this route")]
    MethodNotAllowed(String),
    /// A mesh body that does not parse, or a mesh that fails validation.
    /// The message is the reader's or the validation's own (the code
    /// `invalid_mesh` already says what kind of error it is: clients show
    /// `code: message`, which read "invalid mesh: invalid mesh: …" when
    /// both said it).
    #[error("{0}")]
    InvalidMesh(String),
    /// Mesh format not known or not given.
    #[error("unsupported mesh format: {0}")]
    UnsupportedFormat(String),
    /// Solver parameters out of range.
    #[error("invalid parameters: {0}")]
    InvalidParams(String),
    /// A constraints spec that does not describe a valid constraint set.
    #[error("invalid constraints: {0}")]
    InvalidConstraints(String),
    /// A vertex index beyond the mesh.
    #[error("{0}")]
    VertexOutOfRange(String),
    /// A constraint names a group (`{"group": …}`) the mesh's asset does
    /// not have; the message lists the ones it has.
    #[error("{0}")]
    UnknownGroup(String),
    /// A joint selector (`{"joint": …}`) names a joint the mesh's skin
    /// does not have; the message lists the ones it has.
    #[error("{0}")]
    UnknownJoint(String),
    /// A rig operation (a joint selector, a skeleton export) on a mesh
    /// that is not a skinned glTF/GLB, or whose meshes use several skins.
    #[error("{0}")]
    NotSkinned(String),
    /// The mesh's skin data is broken (joints or weights missing or out of
    /// range, bad inverse bind matrices).
    #[error("{0}")]
    BadSkin(String),
    /// NaN or infinity in a delta or parameter.
    #[error("{0}")]
    NonFinite(String),
    /// No mesh with this id.
    #[error("no mesh `{0}`")]
    MeshNotFound(String),
    /// `DELETE /v1/meshes/{id}` while sessions still edit the mesh. Fix:
    /// delete those sessions first.
    #[error("mesh `{mesh}` is used by {sessions} session(s)")]
    MeshInUse {
        /// The mesh id.
        mesh: String,
        /// How many sessions use it.
        sessions: usize,
    },
    /// No session with this id.
    #[error("no session `{0}`")]
    SessionNotFound(String),
    /// No handle with this index or name.
    #[error("{0}")]
    UnknownHandle(String),
    /// No such route.
    #[error("no route {0}")]
    RouteNotFound(String),
    /// No `Authorization: Bearer` token (or WebSocket `token`).
    #[error("missing access token")]
    MissingToken,
    /// A token that does not open this session.
    #[error("access denied")]
    WrongToken,
    /// Drag/undo before the factor is ready.
    #[error("{0}")]
    NotReady(String),
    /// The handle is held by another client.
    #[error("{0}")]
    HandleGrabbed(String),
    /// Undo with no earlier history entry.
    #[error("{0}")]
    NothingToUndo(String),
    /// Redo with no later history entry.
    #[error("{0}")]
    NothingToRedo(String),
    /// A constraint edit based on a replaced constraint set.
    #[error("{0}")]
    StaleConstraints(String),
    /// The solver failed on this input (not positive definite, diverged...).
    #[error("solve failed: {0}")]
    SolveFailed(String),
    /// Request body over `max_upload_bytes`.
    #[error("request body over the limit of {0} bytes")]
    PayloadTooLarge(usize),
    /// Mesh over `max_vertices`.
    #[error("mesh has {got} vertices, the limit is {limit}")]
    TooManyVertices {
        /// Vertices in the upload.
        got: usize,
        /// The configured limit.
        limit: usize,
    },
    /// WebSocket messages over `ws_max_messages_per_sec`.
    #[error("too many messages; the limit is {0} per second")]
    RateLimited(u32),
    /// `max_sessions` live sessions already.
    #[error("too many sessions (limit {0}); try again later")]
    TooManySessions(usize),
    /// Admission control: `waiting` sessions wait for a solver worker, at
    /// or past the configured `limit`. A new session is refused (existing
    /// ones keep running). Fix: retry after the `Retry-After` seconds, or
    /// on another instance.
    #[error("the server is overloaded ({waiting} sessions wait for a solver, limit {limit}); retry in {} s", OVERLOADED_RETRY_AFTER_SECS)]
    Overloaded {
        /// Sessions waiting for a solver worker.
        waiting: usize,
        /// The admission limit.
        limit: usize,
    },
    /// The instance is shutting down (SIGTERM, a rolling restart): it takes
    /// no new session and is not ready. Fix: retry; the load balancer
    /// routes to another instance.
    #[error("this instance is shutting down; retry (another instance takes over)")]
    Draining,
    /// `max_meshes` meshes stored already.
    #[error("too many meshes (limit {0})")]
    TooManyMeshes(usize),
    /// The request took longer than `request_timeout_secs`.
    #[error("request timed out")]
    Timeout,
    /// The session was closed meanwhile.
    #[error("session closed")]
    SessionClosed,
    /// The store cannot be reached (a database restart, a network fault):
    /// nothing was written and nothing acknowledged. Fix: retry shortly;
    /// `GET /healthz/ready` says when the instance is ready again.
    #[error("the session store is unavailable; retry shortly")]
    StoreUnavailable(String),
    /// Another live instance holds the session's lease: this one does not
    /// drive it. Behind the load balancer (consistent hashing on the
    /// session id) requests normally reach the owner; after a failover the
    /// lease expires within `retry_after_ms` and another instance takes
    /// the session over. Fix: retry after that long.
    #[error("session `{session}` is owned by instance `{owner}`; retry in {retry_after_ms} ms")]
    SessionOwnedElsewhere {
        /// The session.
        session: String,
        /// The owning instance's id.
        owner: String,
        /// When its lease expires unless renewed.
        retry_after_ms: u64,
    },
    /// No named pose of this name in the session.
    #[error("{0}")]
    PoseNotFound(String),
    /// A named pose of this name exists already (rename).
    #[error("{0}")]
    PoseExists(String),
    /// A pose name that is empty, too long or has control characters.
    #[error("{0}")]
    InvalidPoseName(String),
    /// The session has the most named poses it may keep.
    #[error("{0}")]
    TooManyPoses(String),
    /// An export option the session's mesh cannot honour (morph targets
    /// of a mesh uploaded without a glTF/GLB file).
    #[error("{0}")]
    UnsupportedExport(String),
    /// Anything else: logged, reported generically.
    #[error("internal error")]
    Internal(String),
}

/// The JSON error body.
#[derive(Debug, Serialize, serde::Deserialize, PartialEq)]
pub struct ErrorBody {
    /// Stable machine-readable code (see [`ApiError::code`]).
    pub code: String,
    /// Human-readable message.
    pub message: String,
}

impl ApiError {
    /// THE table: stable code and HTTP status of each error.
    pub fn code_status(&self) -> (&'static str, StatusCode) {
        use ApiError::*;
        match self {
            InvalidJson(_) => ("invalid_json", StatusCode::BAD_REQUEST),
            UnsupportedMediaType(_) => {
                ("unsupported_media_type", StatusCode::UNSUPPORTED_MEDIA_TYPE)
            }
            InvalidQuery(_) => ("invalid_query", StatusCode::BAD_REQUEST),
            InvalidPath(_) => ("invalid_path", StatusCode::BAD_REQUEST),
            InvalidUpgrade(_) => ("invalid_upgrade", StatusCode::BAD_REQUEST),
            MethodNotAllowed(_) => ("method_not_allowed", StatusCode::METHOD_NOT_ALLOWED),
            InvalidMesh(_) => ("invalid_mesh", StatusCode::UNPROCESSABLE_ENTITY),
            UnsupportedFormat(_) => ("unsupported_format", StatusCode::UNSUPPORTED_MEDIA_TYPE),
            InvalidParams(_) => ("invalid_params", StatusCode::UNPROCESSABLE_ENTITY),
            InvalidConstraints(_) => ("invalid_constraints", StatusCode::UNPROCESSABLE_ENTITY),
            VertexOutOfRange(_) => ("vertex_out_of_range", StatusCode::UNPROCESSABLE_ENTITY),
            UnknownGroup(_) => ("unknown_group", StatusCode::UNPROCESSABLE_ENTITY),
            UnknownJoint(_) => ("unknown_joint", StatusCode::UNPROCESSABLE_ENTITY),
            NotSkinned(_) => ("not_skinned", StatusCode::UNPROCESSABLE_ENTITY),
            BadSkin(_) => ("bad_skin", StatusCode::UNPROCESSABLE_ENTITY),
            NonFinite(_) => ("non_finite", StatusCode::UNPROCESSABLE_ENTITY),
            MeshNotFound(_) => ("mesh_not_found", StatusCode::NOT_FOUND),
            SessionNotFound(_) => ("session_not_found", StatusCode::NOT_FOUND),
            UnknownHandle(_) => ("unknown_handle", StatusCode::UNPROCESSABLE_ENTITY),
            RouteNotFound(_) => ("route_not_found", StatusCode::NOT_FOUND),
            MissingToken => ("missing_token", StatusCode::UNAUTHORIZED),
            WrongToken => ("forbidden", StatusCode::FORBIDDEN),
            NotReady(_) => ("not_ready", StatusCode::CONFLICT),
            MeshInUse { .. } => ("mesh_in_use", StatusCode::CONFLICT),
            HandleGrabbed(_) => ("handle_grabbed", StatusCode::CONFLICT),
            NothingToUndo(_) => ("nothing_to_undo", StatusCode::CONFLICT),
            NothingToRedo(_) => ("nothing_to_redo", StatusCode::CONFLICT),
            StaleConstraints(_) => ("stale_constraints", StatusCode::CONFLICT),
            SolveFailed(_) => ("solve_failed", StatusCode::UNPROCESSABLE_ENTITY),
            PayloadTooLarge(_) => ("payload_too_large", StatusCode::PAYLOAD_TOO_LARGE),
            TooManyVertices { .. } => ("too_many_vertices", StatusCode::PAYLOAD_TOO_LARGE),
            RateLimited(_) => ("rate_limited", StatusCode::TOO_MANY_REQUESTS),
            TooManySessions(_) => ("too_many_sessions", StatusCode::SERVICE_UNAVAILABLE),
            Overloaded { .. } => ("overloaded", StatusCode::SERVICE_UNAVAILABLE),
            Draining => ("draining", StatusCode::SERVICE_UNAVAILABLE),
            TooManyMeshes(_) => ("too_many_meshes", StatusCode::SERVICE_UNAVAILABLE),
            Timeout => ("timeout", StatusCode::REQUEST_TIMEOUT),
            SessionClosed => ("session_closed", StatusCode::GONE),
            StoreUnavailable(_) => ("store_unavailable", StatusCode::SERVICE_UNAVAILABLE),
            SessionOwnedElsewhere { .. } => ("session_owned_elsewhere", StatusCode::CONFLICT),
            PoseNotFound(_) => ("pose_not_found", StatusCode::NOT_FOUND),
            PoseExists(_) => ("pose_exists", StatusCode::CONFLICT),
            InvalidPoseName(_) => ("invalid_pose_name", StatusCode::UNPROCESSABLE_ENTITY),
            TooManyPoses(_) => ("too_many_poses", StatusCode::CONFLICT),
            UnsupportedExport(_) => ("unsupported_export", StatusCode::UNPROCESSABLE_ENTITY),
            Internal(_) => ("internal", StatusCode::INTERNAL_SERVER_ERROR),
        }
    }

    /// The stable code.
    pub fn code(&self) -> &'static str {
        self.code_status().0
    }

    /// The JSON body (internal details replaced by a generic message).
    pub fn body(&self) -> ErrorBody {
        match self {
            ApiError::Internal(detail) => tracing::error!(%detail, "internal error"),
            ApiError::StoreUnavailable(detail) => tracing::warn!(%detail, "store unavailable"),
            _ => {}
        }
        ErrorBody {
            code: self.code().to_owned(),
            message: self.to_string(),
        }
    }
}

/// The `Retry-After` of a 503 `overloaded`, seconds.
pub const OVERLOADED_RETRY_AFTER_SECS: u64 = 2;

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.code_status().1;
        let retry_after = match self {
            ApiError::Overloaded { .. } => Some(OVERLOADED_RETRY_AFTER_SECS),
            ApiError::Draining => Some(1),
            _ => None,
        };
        if let Some(secs) = retry_after {
            let retry = [(axum::http::header::RETRY_AFTER, secs.to_string())];
            return (status, retry, axum::Json(self.body())).into_response();
        }
        (status, axum::Json(self.body())).into_response()
    }
}

/// `axum::extract::Query` with an [`ApiError`] rejection (400
/// `invalid_query`).
#[derive(Debug, FromRequestParts)]
#[from_request(via(axum::extract::Query), rejection(ApiError))]
pub struct Query<T>(pub T);

/// `axum::extract::Path` with an [`ApiError`] rejection (400
/// `invalid_path`).
#[derive(Debug, FromRequestParts)]
#[from_request(via(axum::extract::Path), rejection(ApiError))]
pub struct Path<T>(pub T);

impl From<JsonRejection> for ApiError {
    fn from(r: JsonRejection) -> Self {
        match r {
            JsonRejection::BytesRejection(b) => b.into(),
            JsonRejection::MissingJsonContentType(m) => {
                ApiError::UnsupportedMediaType(m.body_text())
            }
            other => ApiError::InvalidJson(other.body_text()),
        }
    }
}

impl From<QueryRejection> for ApiError {
    fn from(r: QueryRejection) -> Self {
        ApiError::InvalidQuery(r.body_text())
    }
}

impl From<PathRejection> for ApiError {
    fn from(r: PathRejection) -> Self {
        ApiError::InvalidPath(r.body_text())
    }
}

impl From<WebSocketUpgradeRejection> for ApiError {
    fn from(r: WebSocketUpgradeRejection) -> Self {
        ApiError::InvalidUpgrade(r.body_text())
    }
}

/// The router's answer to a method a route does not serve (axum's own is
/// an empty 405).
pub async fn method_not_allowed(method: axum::http::Method) -> ApiError {
    ApiError::MethodNotAllowed(method.to_string())
}

impl From<BytesRejection> for ApiError {
    fn from(r: BytesRejection) -> Self {
        if r.status() == StatusCode::PAYLOAD_TOO_LARGE {
            // the exact limit is in the config; the message need not repeat it
            ApiError::PayloadTooLarge(0)
        } else {
            ApiError::InvalidJson(r.body_text())
        }
    }
}

impl From<DeformError> for ApiError {
    fn from(e: DeformError) -> Self {
        let msg = e.to_string();
        deform_ref(&e, msg)
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        ApiError::from(&e)
    }
}

impl From<&StoreError> for ApiError {
    /// Unreachable store → 503 `store_unavailable`; a fenced write (the
    /// lease was taken over) → 409 `session_owned_elsewhere`; a session the
    /// store does not hold → 404 `session_not_found`; the rest is internal.
    fn from(e: &StoreError) -> Self {
        match e {
            StoreError::Unavailable(m) => ApiError::StoreUnavailable(m.clone()),
            StoreError::Missing(id) => ApiError::SessionNotFound(id.clone()),
            StoreError::Fenced { session, owner, .. } => ApiError::SessionOwnedElsewhere {
                session: session.clone(),
                owner: owner.clone().unwrap_or_else(|| "none".into()),
                retry_after_ms: 0,
            },
            other => ApiError::Internal(other.to_string()),
        }
    }
}

impl From<&SessionError> for ApiError {
    fn from(e: &SessionError) -> Self {
        let msg = e.to_string();
        match e {
            SessionError::NotReady { .. } => ApiError::NotReady(msg),
            SessionError::UnknownHandle { .. } => ApiError::UnknownHandle(msg),
            SessionError::NonFinite { .. } => ApiError::NonFinite(msg),
            SessionError::HandleGrabbed { .. } => ApiError::HandleGrabbed(msg),
            SessionError::NothingToUndo => ApiError::NothingToUndo(msg),
            SessionError::NothingToRedo => ApiError::NothingToRedo(msg),
            SessionError::StaleConstraints { .. } => ApiError::StaleConstraints(msg),
            SessionError::UnknownPose { .. } => ApiError::PoseNotFound(msg),
            SessionError::PoseExists { .. } => ApiError::PoseExists(msg),
            SessionError::InvalidPoseName { .. } => ApiError::InvalidPoseName(msg),
            SessionError::TooManyPoses { .. } => ApiError::TooManyPoses(msg),
            SessionError::InvalidConstraints(m) => ApiError::InvalidConstraints(m.clone()),
            SessionError::Deform(d) => deform_ref(d, msg),
            SessionError::Store(s) => ApiError::from(s),
            SessionError::Shared(inner) => ApiError::from(&**inner),
            SessionError::Closed => ApiError::SessionClosed,
        }
    }
}

fn deform_ref(d: &DeformError, msg: String) -> ApiError {
    match d {
        DeformError::UnknownVertex { .. } => ApiError::VertexOutOfRange(msg),
        DeformError::InvalidParam { .. } | DeformError::Unsupported { .. } => {
            ApiError::InvalidParams(msg)
        }
        DeformError::NonFinite { .. } => ApiError::NonFinite(msg),
        DeformError::Mesh(_) => ApiError::InvalidMesh(msg),
        DeformError::EmptyHandle { .. }
        | DeformError::DuplicateHandle { .. }
        | DeformError::OverlappingSets { .. }
        | DeformError::NoConstraints
        | DeformError::Unconstrained { .. }
        | DeformError::InvalidTransform { .. }
        | DeformError::PositionsMismatch { .. } => ApiError::InvalidConstraints(msg),
        DeformError::UnknownGroup { .. } => ApiError::UnknownGroup(msg),
        DeformError::Rig(r) => rig_error(r, msg),
        DeformError::OutOfMemory { .. } => ApiError::Internal(msg),
        DeformError::NotPositiveDefinite { .. }
        | DeformError::PoseLength { .. }
        | DeformError::FactorMismatch => ApiError::SolveFailed(msg),
    }
}

/// A rig error as the API reports it.
pub(crate) fn rig_error(r: &dend::rig::RigError, msg: String) -> ApiError {
    use dend::mesh::io::gltf::SkinError;
    use dend::rig::RigError;
    match r {
        RigError::UnknownJoint { .. } => ApiError::UnknownJoint(msg),
        RigError::NotGltf { .. }
        | RigError::Skin(SkinError::NotSkinned | SkinError::SeveralSkins { .. }) => {
            ApiError::NotSkinned(msg)
        }
        RigError::Skin(_) => ApiError::BadSkin(msg),
        RigError::ExportFormat { .. } => ApiError::UnsupportedExport(msg),
        RigError::PoseSize { .. } => ApiError::Internal(msg),
    }
}

impl From<SessionError> for ApiError {
    fn from(e: SessionError) -> Self {
        ApiError::from(&e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_unique_and_internal_details_hidden() {
        let all = [
            ApiError::InvalidJson(String::new()),
            ApiError::UnsupportedMediaType(String::new()),
            ApiError::InvalidQuery(String::new()),
            ApiError::InvalidPath(String::new()),
            ApiError::InvalidUpgrade(String::new()),
            ApiError::MethodNotAllowed(String::new()),
            ApiError::InvalidMesh(String::new()),
            ApiError::UnsupportedFormat(String::new()),
            ApiError::InvalidParams(String::new()),
            ApiError::InvalidConstraints(String::new()),
            ApiError::VertexOutOfRange(String::new()),
            ApiError::NonFinite(String::new()),
            ApiError::MeshNotFound(String::new()),
            ApiError::SessionNotFound(String::new()),
            ApiError::UnknownHandle(String::new()),
            ApiError::RouteNotFound(String::new()),
            ApiError::MissingToken,
            ApiError::WrongToken,
            ApiError::NotReady(String::new()),
            ApiError::HandleGrabbed(String::new()),
            ApiError::NothingToUndo(String::new()),
            ApiError::NothingToRedo(String::new()),
            ApiError::StaleConstraints(String::new()),
            ApiError::SolveFailed(String::new()),
            ApiError::PayloadTooLarge(1),
            ApiError::TooManyVertices { got: 2, limit: 1 },
            ApiError::RateLimited(1),
            ApiError::TooManySessions(1),
            ApiError::Overloaded {
                waiting: 2,
                limit: 1,
            },
            ApiError::Draining,
            ApiError::TooManyMeshes(1),
            ApiError::Timeout,
            ApiError::SessionClosed,
            ApiError::StoreUnavailable("connection refused".into()),
            ApiError::SessionOwnedElsewhere {
                session: "s".into(),
                owner: "i2".into(),
                retry_after_ms: 5,
            },
            ApiError::PoseNotFound(String::new()),
            ApiError::PoseExists(String::new()),
            ApiError::InvalidPoseName(String::new()),
            ApiError::TooManyPoses(String::new()),
            ApiError::UnsupportedExport(String::new()),
            ApiError::Internal("secret path /etc".into()),
        ];
        let mut codes: Vec<_> = all.iter().map(|e| e.code()).collect();
        codes.sort_unstable();
        codes.dedup();
        assert_eq!(codes.len(), all.len());
        let unavailable = ApiError::from(StoreError::Unavailable("refused".into()));
        assert_eq!(
            unavailable.code_status(),
            ("store_unavailable", StatusCode::SERVICE_UNAVAILABLE)
        );
        let fenced = ApiError::from(StoreError::Fenced {
            session: "s".into(),
            fence: 1,
            current: Some(2),
            owner: Some("dend2".into()),
        });
        assert_eq!(fenced.code(), "session_owned_elsewhere");
        assert!(fenced.to_string().contains("dend2"), "{fenced}");
        let body = ApiError::Internal("secret path /etc".into()).body();
        assert!(!body.message.contains("secret"));
        assert_eq!(ApiError::WrongToken.code_status().1, StatusCode::FORBIDDEN);
        assert_eq!(
            ApiError::MissingToken.code_status().1,
            StatusCode::UNAUTHORIZED
        );
    }
}
