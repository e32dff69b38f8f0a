//! The error body of the HTTP API and the WebSocket `error` message:
//! [`ErrorBody`] `{code, message}`, with [`ErrorCode`] the stable codes.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Declares [`ErrorCode`] with each variant's wire string, once.
macro_rules! error_codes {
    ($($(#[$m:meta])* $variant:ident = $wire:literal,)*) => {
        /// A stable, machine-readable error code, serialised as its
        /// snake_case string (the wire strings never change: clients
        /// match them). A code this build does not know (a newer server's)
        /// is kept as [`ErrorCode::Other`].
        #[derive(Debug, Clone, PartialEq, Eq, Hash)]
        pub enum ErrorCode {
            $($(#[$m])* $variant,)*
            /// A code this build does not know.
            Other(String),
        }

        impl ErrorCode {
            /// Every code this build knows.
            pub const ALL: &'static [ErrorCode] = &[$(ErrorCode::$variant),*];

            /// The wire string.
            pub fn as_str(&self) -> &str {
                match self {
                    $(ErrorCode::$variant => $wire,)*
                    ErrorCode::Other(s) => s,
                }
            }
        }

        impl FromStr for ErrorCode {
            type Err = std::convert::Infallible;

            /// Never fails: an unknown code is [`ErrorCode::Other`].
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                Ok(match s {
                    $($wire => ErrorCode::$variant,)*
                    other => ErrorCode::Other(other.to_owned()),
                })
            }
        }
    };
}

error_codes! {
    /// The body is not valid JSON or does not match the expected shape.
    InvalidJson = "invalid_json",
    /// A JSON body sent without `Content-Type: application/json`.
    UnsupportedMediaType = "unsupported_media_type",
    /// A query string that does not parse or has unknown parameters.
    InvalidQuery = "invalid_query",
    /// A path parameter that does not parse.
    InvalidPath = "invalid_path",
    /// A request to the WebSocket route that is not an upgrade.
    InvalidUpgrade = "invalid_upgrade",
    /// The route does not serve this method.
    MethodNotAllowed = "method_not_allowed",
    /// A mesh that does not parse or fails validation.
    InvalidMesh = "invalid_mesh",
    /// A mesh format not known or not given.
    UnsupportedFormat = "unsupported_format",
    /// Solver parameters out of range.
    InvalidParams = "invalid_params",
    /// A constraints spec that does not describe a valid constraint set.
    InvalidConstraints = "invalid_constraints",
    /// A vertex index beyond the mesh.
    VertexOutOfRange = "vertex_out_of_range",
    /// A group name the mesh's asset does not have.
    UnknownGroup = "unknown_group",
    /// A joint name or index the mesh's skin does not have.
    UnknownJoint = "unknown_joint",
    /// A rig operation on a mesh that is not a skinned glTF/GLB (or whose
    /// meshes use several skins).
    NotSkinned = "not_skinned",
    /// The mesh's skin data is broken (joints or weights out of range, bad
    /// inverse bind matrices).
    BadSkin = "bad_skin",
    /// NaN, infinite or null where a number is needed.
    NonFinite = "non_finite",
    /// No such mesh.
    MeshNotFound = "mesh_not_found",
    /// No such session.
    SessionNotFound = "session_not_found",
    /// No such handle in the session's constraint set.
    UnknownHandle = "unknown_handle",
    /// No such route.
    RouteNotFound = "route_not_found",
    /// No bearer token.
    MissingToken = "missing_token",
    /// The bearer token is not the session's.
    Forbidden = "forbidden",
    /// The session's factor is not ready.
    NotReady = "not_ready",
    /// Sessions still use the mesh.
    MeshInUse = "mesh_in_use",
    /// Another client holds the handle.
    HandleGrabbed = "handle_grabbed",
    /// The history has nothing to undo.
    NothingToUndo = "nothing_to_undo",
    /// The history has nothing to redo.
    NothingToRedo = "nothing_to_redo",
    /// Another constraint edit came first (`If-Match`).
    StaleConstraints = "stale_constraints",
    /// The solver failed.
    SolveFailed = "solve_failed",
    /// The body is over the upload limit.
    PayloadTooLarge = "payload_too_large",
    /// The mesh has more vertices than allowed.
    TooManyVertices = "too_many_vertices",
    /// Too many WebSocket messages per second.
    RateLimited = "rate_limited",
    /// The instance has the most sessions it may hold.
    TooManySessions = "too_many_sessions",
    /// Too many sessions wait for a solver worker.
    Overloaded = "overloaded",
    /// The instance is draining (a rolling restart).
    Draining = "draining",
    /// The store has the most meshes it may hold.
    TooManyMeshes = "too_many_meshes",
    /// The request took longer than the request timeout.
    Timeout = "timeout",
    /// The session was closed.
    SessionClosed = "session_closed",
    /// The store cannot be reached.
    StoreUnavailable = "store_unavailable",
    /// Another instance holds the session's lease.
    SessionOwnedElsewhere = "session_owned_elsewhere",
    /// No such named pose.
    PoseNotFound = "pose_not_found",
    /// A named pose of that name exists.
    PoseExists = "pose_exists",
    /// A pose name that is empty, too long or has control characters.
    InvalidPoseName = "invalid_pose_name",
    /// The session has the most named poses it may keep.
    TooManyPoses = "too_many_poses",
    /// An export option the session's mesh cannot honour.
    UnsupportedExport = "unsupported_export",
    /// An internal failure (details in the server's log).
    Internal = "internal",
}

impl fmt::Display for ErrorCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for ErrorCode {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for ErrorCode {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        Ok(s.parse().unwrap_or_else(|never| match never {}))
    }
}

impl Default for ErrorCode {
    /// [`ErrorCode::Internal`]: what a client reports for an error answer
    /// without a readable body.
    fn default() -> Self {
        ErrorCode::Internal
    }
}

/// The JSON error body of every failed request: `{code, message}`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ErrorBody {
    /// The stable machine-readable code.
    #[serde(default)]
    pub code: ErrorCode,
    /// A human-readable message.
    #[serde(default)]
    pub message: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every code round-trips through its wire string, and the strings are
    /// distinct snake_case words.
    #[test]
    fn codes_round_trip_through_their_strings() {
        let mut seen = std::collections::HashSet::new();
        for c in ErrorCode::ALL {
            let s = c.as_str();
            assert!(
                s.chars().all(|ch| ch.is_ascii_lowercase() || ch == '_'),
                "{s}"
            );
            assert!(seen.insert(s), "{s} twice");
            let json = serde_json::to_string(c).expect("serialise");
            assert_eq!(json, format!("\"{s}\""));
            let back: ErrorCode = serde_json::from_str(&json).expect("deserialise");
            assert_eq!(&back, c);
        }
    }

    /// A code this build does not know survives as `Other`, unchanged.
    #[test]
    fn an_unknown_code_is_kept() {
        let b: ErrorBody =
            serde_json::from_str(r#"{"code":"brand_new","message":"m"}"#).expect("body");
        assert_eq!(b.code, ErrorCode::Other("brand_new".into()));
        assert_eq!(serde_json::to_value(&b).expect("json")["code"], "brand_new");
    }
}
