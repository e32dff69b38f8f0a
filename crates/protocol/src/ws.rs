//! The session socket's JSON messages (`GET /v1/sessions/{id}/ws`, see
//! `api/ws-protocol.md`) and the session requests and answers that share
//! their types: what a client sends ([`ClientMsg`]), what the server
//! answers besides the binary pose frames ([`ServerMsg`]), and the stream
//! options a client picks when it connects ([`StreamOptions`]).
//!
//! These are the raw shapes on the wire: numbers a client may send as
//! `null` (JavaScript's NaN) are `Option`s here, and the server validates
//! them at its edge.

use serde::{Deserialize, Serialize};

use crate::constraints::{ConstraintWarning, ConstraintsSpec};
use crate::error::ErrorCode;
use crate::frame::FrameEncoding;
use crate::params::SessionParams;

/// Client id within a session (assigned when a socket joins).
pub type ClientId = u64;

/// A handle named by its index in the constraints' `handles` or by name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum HandleRef {
    /// Index into the constraints' handle list.
    Index(usize),
    /// The handle's `name`.
    Name(String),
}

impl std::fmt::Display for HandleRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            HandleRef::Index(i) => write!(f, "#{i}"),
            HandleRef::Name(n) => write!(f, "`{n}`"),
        }
    }
}

impl From<usize> for HandleRef {
    fn from(i: usize) -> Self {
        HandleRef::Index(i)
    }
}

impl From<&str> for HandleRef {
    fn from(n: &str) -> Self {
        HandleRef::Name(n.to_owned())
    }
}

/// A rotation as axis + degrees.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct AxisAngle {
    /// Rotation axis (any length > 0).
    pub axis: [Option<f64>; 3],
    /// Angle in degrees (right-hand rule).
    pub degrees: Option<f64>,
}

/// The delta fields of a drag (HTTP body and WebSocket message): rotate
/// about the handle's current pivot, then translate. Numbers are `Option`
/// because JavaScript's `JSON.stringify` turns NaN and infinities into
/// `null`: the server answers those with `non_finite`, not `invalid_json`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
pub struct DeltaJson {
    /// Delta translation (mesh units).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translate: Option<[Option<f64>; 3]>,
    /// Delta rotation as axis + degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate: Option<AxisAngle>,
    /// Delta rotation as a quaternion `[x, y, z, w]` (normalised).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quaternion: Option<[Option<f64>; 4]>,
}

impl DeltaJson {
    /// A delta of finite numbers: `translate`, then optionally a rotation
    /// given as a quaternion `[x, y, z, w]`.
    pub fn new(translate: [f64; 3], quaternion: Option<[f64; 4]>) -> Self {
        DeltaJson {
            translate: Some(translate.map(Some)),
            rotate: None,
            quaternion: quaternion.map(|q| q.map(Some)),
        }
    }

    /// A translation.
    pub fn translate(t: [f64; 3]) -> Self {
        DeltaJson::new(t, None)
    }

    /// A rotation by `degrees` about `axis` (right-hand rule).
    pub fn axis_angle(axis: [f64; 3], degrees: f64) -> Self {
        DeltaJson {
            translate: None,
            rotate: Some(AxisAngle {
                axis: axis.map(Some),
                degrees: Some(degrees),
            }),
            quaternion: None,
        }
    }
}

/// The constraint/factor state of a session.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionState {
    /// No constraints set yet.
    Empty,
    /// Constraints set; the factor is being built.
    Building,
    /// The factor is ready: drags are accepted.
    Ready,
    /// Building the factor failed (see the `error` event); set other constraints.
    Failed,
}

/// A stage of a constraint set's factor build, announced as it starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BuildStage {
    /// Assembling the system matrix.
    Assembly,
    /// The sparse Cholesky's symbolic analysis (ordering, elimination tree).
    Symbolic,
    /// The numeric factorisation.
    Numeric,
}

/// A snapshot of a session's public state: `GET /v1/sessions/{id}` and
/// the `state` event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionInfo {
    /// Session id.
    pub id: String,
    /// Mesh id.
    pub mesh_id: String,
    /// Constraint/factor state.
    pub state: SessionState,
    /// Current revision.
    pub revision: u64,
    /// Handle names, by index.
    pub handles: Vec<String>,
    /// Connected WebSocket clients.
    pub peers: usize,
    /// Whether undo would do something.
    pub can_undo: bool,
    /// Whether redo would do something.
    pub can_redo: bool,
    /// Vertex count of the mesh.
    pub vertices: usize,
    /// The installed constraint set (null before the first): as its
    /// client sent it, asset groups resolved into the vertex indices they
    /// name.
    pub constraints: Option<ConstraintsSpec>,
    /// Revision of the constraint set: it changes with every constraint
    /// edit, and with undo, redo or reset to another set. An edit may name
    /// the revision it is based on (`If-Match`, or `if_revision` over
    /// WebSocket) and is then refused with `stale_constraints` (409) if the
    /// set was replaced meanwhile.
    pub constraints_revision: u64,
    /// What the installed constraint set does that its user should know
    /// (the set is valid): `nothing_fixed`, `unconstrained_component`
    /// (`component`, `vertices`), `stray_vertices` (`count`, `vertices`),
    /// each with a readable `message`.
    pub warnings: Vec<ConstraintWarning>,
    /// While the state is `building` and the factor is being built (not
    /// found in the cache): the stage under way, `assembly`, `symbolic` or
    /// `numeric` (in that order; `build_progress` events announce each).
    pub build_stage: Option<BuildStage>,
    /// The named poses, in save order (without their positions).
    #[serde(default)]
    pub poses: Vec<PoseInfo>,
}

/// A named pose as listed: everything but its positions and targets.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PoseInfo {
    /// The name.
    pub name: String,
    /// Position in save order (0 first): the list's order, the morph
    /// targets' and the export animation's.
    pub index: usize,
    /// The session revision of the saved pose.
    pub revision: u64,
    /// When it was saved, seconds since the Unix epoch.
    pub created_unix: u64,
}

/// `POST /v1/sessions` body, parameters typed.
pub type CreateSession = CreateSessionOf<SessionParams>;

/// `POST /v1/sessions` body with parameters of type `P`: [`CreateSession`]
/// for a client; the server reads them as raw JSON first, so that
/// parameters which do not parse are answered `invalid_params`, not
/// `invalid_json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CreateSessionOf<P> {
    /// The mesh to edit.
    pub mesh_id: String,
    /// Solver parameters (all optional).
    #[serde(default)]
    pub params: P,
}

/// `POST /v1/sessions` answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Created {
    /// Session id.
    pub id: String,
    /// Access token (shown once).
    pub token: String,
    /// Mesh id.
    pub mesh_id: String,
    /// State (`empty`).
    pub state: SessionState,
}

/// `POST /v1/sessions/{id}/drag` body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DragRequest {
    /// Handle index or name.
    pub handle: HandleRef,
    /// The delta.
    #[serde(flatten)]
    pub delta: DeltaJson,
    /// Iteration budget (default: the session's `max_iters`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iters: Option<usize>,
}

/// How the server streams pose frames to one connection: chosen with
/// query parameters of the upgrade request (`?window=1&encoding=q16`).
/// Without them the connection gets what protocol version 2 clients
/// expect: version 2 frames (f32) and no flow control.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StreamOptions {
    /// At most this many frames sent and not yet acknowledged by an
    /// [`ClientMsg::Ack`] (1 to [`MAX_WINDOW`]); frames produced meanwhile
    /// are skipped, the latest one is sent when the window opens. `None`:
    /// no flow control (every frame is sent as it is produced).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window: Option<u32>,
    /// The frame encoding; `None`: version 2 frames (f32). Given: version 3
    /// frames in that encoding.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub encoding: Option<FrameEncoding>,
    /// At most this many frames per second (1 to [`MAX_FPS`]): a frame
    /// produced sooner than `1/max_fps` after the last one sent waits (the
    /// latest one is sent when the interval ends). `None`: no cap.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_fps: Option<u32>,
    /// At most this many *refinement* frames per second (1 to
    /// [`MAX_FPS`]): a frame that only refines the pose last sent (same
    /// last drag, same level, more iterations, not settled) waits until
    /// `1/refine_fps` after the last frame sent; a frame that answers a
    /// drag, changes level or is settled goes out as soon as the window
    /// and `max_fps` let it. `None`: refinements are not held back.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refine_fps: Option<u32>,
}

/// The largest flow-control window a client may declare.
pub const MAX_WINDOW: u32 = 64;

/// The largest frame rate a client may declare.
pub const MAX_FPS: u32 = 1000;

impl StreamOptions {
    /// Flow control with `window` frames in flight and version 3 frames
    /// in `encoding`: what the project's clients use.
    pub fn flow(window: u32, encoding: FrameEncoding) -> Self {
        StreamOptions {
            window: Some(window),
            encoding: Some(encoding),
            max_fps: None,
            refine_fps: None,
        }
    }

    /// These options with frames capped at `max_fps` per second.
    pub fn at_most_fps(self, max_fps: u32) -> Self {
        StreamOptions {
            max_fps: Some(max_fps),
            ..self
        }
    }

    /// These options with refinement frames capped at `refine_fps` per
    /// second.
    pub fn refining_at_most(self, refine_fps: u32) -> Self {
        StreamOptions {
            refine_fps: Some(refine_fps),
            ..self
        }
    }

    /// The query string (`window=1&encoding=q16`, empty for the defaults),
    /// without the `?`.
    pub fn to_query(&self) -> String {
        let mut parts = vec![];
        if let Some(w) = self.window {
            parts.push(format!("window={w}"));
        }
        if let Some(e) = self.encoding {
            parts.push(format!("encoding={}", e.name()));
        }
        if let Some(f) = self.max_fps {
            parts.push(format!("max_fps={f}"));
        }
        if let Some(f) = self.refine_fps {
            parts.push(format!("refine_fps={f}"));
        }
        parts.join("&")
    }

    /// Checks the window's range; the message says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(w) = self.window.filter(|w| !(1..=MAX_WINDOW).contains(w)) {
            return Err(format!(
                "`window` must be between 1 and {MAX_WINDOW}, got {w}"
            ));
        }
        for (name, fps) in [("max_fps", self.max_fps), ("refine_fps", self.refine_fps)] {
            if let Some(f) = fps.filter(|f| !(1..=MAX_FPS).contains(f)) {
                return Err(format!("`{name}` must be between 1 and {MAX_FPS}, got {f}"));
            }
        }
        Ok(())
    }
}

/// Client → server messages (JSON, `type` tagged), constraints typed.
pub type ClientMsg = ClientMsgOf<ConstraintsSpec>;

/// Client → server messages with a constraint set of type `C`:
/// [`ClientMsg`] for a client; the server reads the set as raw JSON first,
/// so that a set which does not parse is answered `invalid_constraints`,
/// not `invalid_json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ClientMsgOf<C> {
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
        constraints: C,
        /// The constraints revision the edit is based on: refused with
        /// `stale_constraints` if another edit replaced it (omitted: any).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        if_revision: Option<u64>,
    },
    /// Undo.
    Undo,
    /// Redo.
    Redo,
    /// Save the settled pose under `name`; the `state` that follows lists
    /// it in `poses`. A pose of that name is replaced only with `replace`,
    /// else the save is refused with `pose_exists`.
    SavePose {
        /// The name.
        name: String,
        /// Replace a pose of the same name.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        replace: bool,
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
        #[serde(default, skip_serializing_if = "Option::is_none")]
        nonce: Option<serde_json::Value>,
    },
    /// The client has taken (decoded, or at least received) every frame up
    /// to this session revision: opens the flow-control window (see
    /// [`StreamOptions::window`]). Not counted by the message rate limit.
    Ack {
        /// The revision of the latest frame taken.
        revision: u64,
    },
}

/// What one client of a session did, told to every client
/// (`{"type": "handle_grabbed", "handle": 0, "client": 3}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum PeerEvent {
    /// A client grabbed a handle.
    HandleGrabbed {
        /// Handle index.
        handle: usize,
        /// Who.
        client: ClientId,
    },
    /// A client released a handle.
    HandleReleased {
        /// Handle index.
        handle: usize,
        /// Who.
        client: ClientId,
    },
    /// A client joined.
    PeerJoined {
        /// Who.
        client: ClientId,
    },
    /// A client left.
    PeerLeft {
        /// Who.
        client: ClientId,
    },
}

/// Server → client JSON events (`type` tagged).
// `State` carries the whole session snapshot; the messages live only
// between a socket and its reader, so boxing it would buy nothing
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMsg {
    /// The factor is ready; drags are accepted.
    Ready {
        /// Revision.
        revision: u64,
    },
    /// An error (of this client's message when `seq` is set).
    Error {
        /// Stable code (same table as HTTP).
        code: ErrorCode,
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
        stage: BuildStage,
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
        session: SessionInfo,
    },
    /// A handle grabbed or released, a client joined or left: the
    /// session's [`PeerEvent`] as it is (its own `type` tag).
    #[serde(untagged)]
    Peer(PeerEvent),
}

impl ServerMsg {
    /// The message's `type` tag (`state`, `error`, `handle_grabbed`, …).
    pub fn kind(&self) -> &'static str {
        match self {
            ServerMsg::Ready { .. } => "ready",
            ServerMsg::Error { .. } => "error",
            ServerMsg::BuildProgress { .. } => "build_progress",
            ServerMsg::Pong { .. } => "pong",
            ServerMsg::State { .. } => "state",
            ServerMsg::Peer(PeerEvent::HandleGrabbed { .. }) => "handle_grabbed",
            ServerMsg::Peer(PeerEvent::HandleReleased { .. }) => "handle_released",
            ServerMsg::Peer(PeerEvent::PeerJoined { .. }) => "peer_joined",
            ServerMsg::Peer(PeerEvent::PeerLeft { .. }) => "peer_left",
        }
    }
}
