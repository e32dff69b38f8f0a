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

use crate::session::error::SessionError;
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

/// The JSON error body, the protocol's own (codes and body are defined
/// once, in `dend-protocol`, for the server and every Rust client).
pub use dend_protocol::{ErrorBody, ErrorCode};

impl ApiError {
    /// THE table: stable code and HTTP status of each error.
    pub fn code_status(&self) -> (ErrorCode, StatusCode) {
        use ApiError::*;
        use ErrorCode as C;
        match self {
            InvalidJson(_) => (C::InvalidJson, StatusCode::BAD_REQUEST),
            UnsupportedMediaType(_) => {
                (C::UnsupportedMediaType, StatusCode::UNSUPPORTED_MEDIA_TYPE)
            }
            InvalidQuery(_) => (C::InvalidQuery, StatusCode::BAD_REQUEST),
            InvalidPath(_) => (C::InvalidPath, StatusCode::BAD_REQUEST),
            InvalidUpgrade(_) => (C::InvalidUpgrade, StatusCode::BAD_REQUEST),
            MethodNotAllowed(_) => (C::MethodNotAllowed, StatusCode::METHOD_NOT_ALLOWED),
            InvalidMesh(_) => (C::InvalidMesh, StatusCode::UNPROCESSABLE_ENTITY),
            UnsupportedFormat(_) => (C::UnsupportedFormat, StatusCode::UNSUPPORTED_MEDIA_TYPE),
            InvalidParams(_) => (C::InvalidParams, StatusCode::UNPROCESSABLE_ENTITY),
            InvalidConstraints(_) => (C::InvalidConstraints, StatusCode::UNPROCESSABLE_ENTITY),
            VertexOutOfRange(_) => (C::VertexOutOfRange, StatusCode::UNPROCESSABLE_ENTITY),
            UnknownGroup(_) => (C::UnknownGroup, StatusCode::UNPROCESSABLE_ENTITY),
            UnknownJoint(_) => (C::UnknownJoint, StatusCode::UNPROCESSABLE_ENTITY),
            NotSkinned(_) => (C::NotSkinned, StatusCode::UNPROCESSABLE_ENTITY),
            BadSkin(_) => (C::BadSkin, StatusCode::UNPROCESSABLE_ENTITY),
            NonFinite(_) => (C::NonFinite, StatusCode::UNPROCESSABLE_ENTITY),
            MeshNotFound(_) => (C::MeshNotFound, StatusCode::NOT_FOUND),
            SessionNotFound(_) => (C::SessionNotFound, StatusCode::NOT_FOUND),
            UnknownHandle(_) => (C::UnknownHandle, StatusCode::UNPROCESSABLE_ENTITY),
            RouteNotFound(_) => (C::RouteNotFound, StatusCode::NOT_FOUND),
            MissingToken => (C::MissingToken, StatusCode::UNAUTHORIZED),
            WrongToken => (C::Forbidden, StatusCode::FORBIDDEN),
            NotReady(_) => (C::NotReady, StatusCode::CONFLICT),
            MeshInUse { .. } => (C::MeshInUse, StatusCode::CONFLICT),
            HandleGrabbed(_) => (C::HandleGrabbed, StatusCode::CONFLICT),
            NothingToUndo(_) => (C::NothingToUndo, StatusCode::CONFLICT),
            NothingToRedo(_) => (C::NothingToRedo, StatusCode::CONFLICT),
            StaleConstraints(_) => (C::StaleConstraints, StatusCode::CONFLICT),
            SolveFailed(_) => (C::SolveFailed, StatusCode::UNPROCESSABLE_ENTITY),
            PayloadTooLarge(_) => (C::PayloadTooLarge, StatusCode::PAYLOAD_TOO_LARGE),
            TooManyVertices { .. } => (C::TooManyVertices, StatusCode::PAYLOAD_TOO_LARGE),
            RateLimited(_) => (C::RateLimited, StatusCode::TOO_MANY_REQUESTS),
            TooManySessions(_) => (C::TooManySessions, StatusCode::SERVICE_UNAVAILABLE),
            Overloaded { .. } => (C::Overloaded, StatusCode::SERVICE_UNAVAILABLE),
            Draining => (C::Draining, StatusCode::SERVICE_UNAVAILABLE),
            TooManyMeshes(_) => (C::TooManyMeshes, StatusCode::SERVICE_UNAVAILABLE),
            Timeout => (C::Timeout, StatusCode::REQUEST_TIMEOUT),
            SessionClosed => (C::SessionClosed, StatusCode::GONE),
            StoreUnavailable(_) => (C::StoreUnavailable, StatusCode::SERVICE_UNAVAILABLE),
            SessionOwnedElsewhere { .. } => (C::SessionOwnedElsewhere, StatusCode::CONFLICT),
            PoseNotFound(_) => (C::PoseNotFound, StatusCode::NOT_FOUND),
            PoseExists(_) => (C::PoseExists, StatusCode::CONFLICT),
            InvalidPoseName(_) => (C::InvalidPoseName, StatusCode::UNPROCESSABLE_ENTITY),
            TooManyPoses(_) => (C::TooManyPoses, StatusCode::CONFLICT),
            UnsupportedExport(_) => (C::UnsupportedExport, StatusCode::UNPROCESSABLE_ENTITY),
            Internal(_) => (C::Internal, StatusCode::INTERNAL_SERVER_ERROR),
        }
    }

    /// The stable code.
    pub fn code(&self) -> ErrorCode {
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
            code: self.code(),
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

    /// One error of each kind the server reports.
    fn every_error() -> Vec<ApiError> {
        let s = String::new;
        vec![
            ApiError::InvalidJson(s()),
            ApiError::UnsupportedMediaType(s()),
            ApiError::InvalidQuery(s()),
            ApiError::InvalidPath(s()),
            ApiError::InvalidUpgrade(s()),
            ApiError::MethodNotAllowed(s()),
            ApiError::InvalidMesh(s()),
            ApiError::UnsupportedFormat(s()),
            ApiError::InvalidParams(s()),
            ApiError::InvalidConstraints(s()),
            ApiError::VertexOutOfRange(s()),
            ApiError::UnknownGroup(s()),
            ApiError::UnknownJoint(s()),
            ApiError::NotSkinned(s()),
            ApiError::BadSkin(s()),
            ApiError::NonFinite(s()),
            ApiError::MeshNotFound(s()),
            ApiError::MeshInUse {
                mesh: "m".into(),
                sessions: 2,
            },
            ApiError::SessionNotFound(s()),
            ApiError::UnknownHandle(s()),
            ApiError::RouteNotFound(s()),
            ApiError::MissingToken,
            ApiError::WrongToken,
            ApiError::NotReady(s()),
            ApiError::HandleGrabbed(s()),
            ApiError::NothingToUndo(s()),
            ApiError::NothingToRedo(s()),
            ApiError::StaleConstraints(s()),
            ApiError::SolveFailed(s()),
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
            ApiError::PoseNotFound(s()),
            ApiError::PoseExists(s()),
            ApiError::InvalidPoseName(s()),
            ApiError::TooManyPoses(s()),
            ApiError::UnsupportedExport(s()),
            ApiError::Internal("secret path /etc".into()),
        ]
    }

    #[test]
    fn codes_are_unique_and_internal_details_hidden() {
        let all = every_error();
        let mut codes: Vec<_> = all.iter().map(|e| e.code()).collect();
        codes.sort_unstable_by(|a, b| a.as_str().cmp(b.as_str()));
        codes.dedup();
        assert_eq!(codes.len(), all.len());
        let unavailable = ApiError::from(StoreError::Unavailable("refused".into()));
        assert_eq!(
            unavailable.code_status(),
            (ErrorCode::StoreUnavailable, StatusCode::SERVICE_UNAVAILABLE)
        );
        let fenced = ApiError::from(StoreError::Fenced {
            session: "s".into(),
            fence: 1,
            current: Some(2),
            owner: Some("dend2".into()),
        });
        assert_eq!(fenced.code(), ErrorCode::SessionOwnedElsewhere);
        assert!(fenced.to_string().contains("dend2"), "{fenced}");
        let body = ApiError::Internal("secret path /etc".into()).body();
        assert!(!body.message.contains("secret"));
        assert_eq!(ApiError::WrongToken.code_status().1, StatusCode::FORBIDDEN);
        assert_eq!(
            ApiError::MissingToken.code_status().1,
            StatusCode::UNAUTHORIZED
        );
    }

    /// Every code the server emits is one the protocol knows (never
    /// `Other`), reads back from its wire string as itself, in the HTTP body
    /// and the WebSocket `error` event alike; and the protocol lists no code
    /// the server never sends.
    #[test]
    fn every_code_round_trips_through_the_wire_and_the_protocol_has_no_extra() {
        use dend_protocol::ServerMsg;
        let mut emitted = std::collections::HashSet::new();
        for e in every_error() {
            let code = e.code();
            assert!(!matches!(code, ErrorCode::Other(_)), "{e:?}: {code:?}");
            let wire = serde_json::to_value(e.body()).expect("body");
            assert_eq!(wire["code"], code.as_str(), "{e:?}");
            let back: ErrorBody = serde_json::from_value(wire).expect("read back");
            assert_eq!(back.code, code);
            assert_eq!(back.message, e.body().message);
            let event = ServerMsg::Error {
                code: code.clone(),
                message: back.message,
                seq: Some(3),
            };
            let text = serde_json::to_string(&event).expect("event");
            let read: ServerMsg = serde_json::from_str(&text).expect("event back");
            assert_eq!(read, event, "{text}");
            emitted.insert(code);
        }
        let known: std::collections::HashSet<_> = ErrorCode::ALL.iter().cloned().collect();
        assert_eq!(emitted, known);
        // a newer server's code survives an older client: kept as `Other`
        let body: ErrorBody =
            serde_json::from_str(r#"{"code": "quota_exceeded", "message": "m"}"#).expect("body");
        assert_eq!(body.code, ErrorCode::Other("quota_exceeded".into()));
        assert_eq!(
            serde_json::to_value(&body).expect("json")["code"],
            "quota_exceeded"
        );
    }
}
