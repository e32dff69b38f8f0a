//! A small Rust client of the dend server (HTTP + WebSocket), used by the
//! end-to-end tests and `dend loadtest`, usable by tool backends.
//!
//! ```no_run
//! # async fn demo() -> Result<(), dend_client::ClientError> {
//! use dend_client::Client;
//! let c = Client::new("http://127.0.0.1:8080");
//! let mesh = c.upload_json(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &[[0, 1, 2]]).await?;
//! let s = c.create_session(&mesh.id, dend_client::SessionParams::default()).await?;
//! let mut ws = s.connect().await?;
//! ws.drag(0, [0.0, 0.0, 0.1], None, 1).await?;
//! let (header, positions) = ws.frame_acking(1, false).await?;
//! # let _ = (header, positions);
//! # Ok(()) }
//! ```

mod client;
mod error;
pub mod gesture;
mod poses;
mod session;
mod socket;

pub use client::Client;
pub use error::ClientError;
pub use session::SessionClient;
pub use socket::{WsClient, WsEvent, WsFull};

/// The wire types (messages, session info, stream options).
pub use dend_protocol::ws;
/// How version 3 frames store positions.
pub use dend_protocol::FrameEncoding;
/// A mesh as the API describes it (the server's own type).
pub use dend_protocol::MeshInfo;
/// A pose as JSON (the server's own type).
pub use dend_protocol::PoseJson as Pose;
/// What a client sends: session parameters and constraints (typed), the
/// server's answers about them, curvatures, presets and named poses.
pub use dend_protocol::{
    constraints, params, ConstraintWarning, ConstraintsAccepted, ConstraintsSpec, Curvature,
    GenerateMesh, HandleSpec, MeshJson, NamedPose, PoseList, PresetInfo, PresetList, RenamePose,
    RotationSpec, SavePose, SessionParams, ShapeParams, VertexSet, WarningKind,
};
/// The error body of a failed request and its stable codes (the server's
/// own types).
pub use dend_protocol::{ErrorBody, ErrorCode};
