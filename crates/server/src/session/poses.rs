//! Named poses: a session's settled pose saved under a name, listed,
//! renamed, deleted and restored (an undo step), kept in the store
//! ([`NamedPose`]) and read back when the session's actor starts (so a
//! revived or failed-over session has them). The export writes them as
//! glTF morph targets (`crate::morph_export`).

use std::sync::Arc;

use super::error::SessionError;
use super::handle::SessionHandle;
use super::shared::{Cmd, PoseCmd, Reply};
use super::types::PoseSnapshot;
use crate::store::NamedPose;

/// Most named poses a session keeps.
pub const MAX_NAMED_POSES: usize = 64;

/// Longest pose name, in bytes.
pub const MAX_POSE_NAME_BYTES: usize = 128;

pub use dend_protocol::ws::PoseInfo;

/// The listing of `poses` (in their order).
pub fn pose_list(poses: &[NamedPose]) -> Vec<PoseInfo> {
    poses
        .iter()
        .enumerate()
        .map(|(index, p)| PoseInfo {
            name: p.name.clone(),
            index,
            revision: p.revision,
            created_unix: p.created_unix,
        })
        .collect()
}

/// Checks a pose name: 1 to [`MAX_POSE_NAME_BYTES`] bytes, no control
/// characters, not only white space.
pub fn check_pose_name(name: &str) -> Result<(), SessionError> {
    let bad = |reason: &str| {
        Err(SessionError::InvalidPoseName {
            reason: reason.into(),
        })
    };
    if name.trim().is_empty() {
        return bad("a pose name must not be empty or only white space");
    }
    if name.len() > MAX_POSE_NAME_BYTES {
        return bad(&format!(
            "a pose name is at most {MAX_POSE_NAME_BYTES} bytes"
        ));
    }
    if name.chars().any(char::is_control) {
        return bad("a pose name must not contain control characters");
    }
    Ok(())
}

impl SessionHandle {
    async fn pose_call<T>(
        &self,
        make: impl FnOnce(Reply<T>) -> PoseCmd,
    ) -> Result<T, SessionError> {
        self.call(|reply| Cmd::Poses(make(reply))).await
    }

    /// Saves the current pose under `name` once the session has settled.
    /// A pose of the same name is replaced (in its place) only when
    /// `replace` is set, else the save is refused with `PoseExists`: a
    /// name typed twice must not lose the first pose silently.
    pub async fn save_pose(&self, name: &str, replace: bool) -> Result<PoseInfo, SessionError> {
        check_pose_name(name)?;
        let name = name.to_owned();
        self.pose_call(|reply| PoseCmd::Save {
            name,
            replace,
            reply,
        })
        .await
    }

    /// The named poses, in save order, with their positions.
    pub async fn named_poses(&self) -> Result<Arc<Vec<NamedPose>>, SessionError> {
        self.pose_call(PoseCmd::List).await
    }

    /// Renames pose `from` to `to`.
    pub async fn rename_pose(&self, from: &str, to: &str) -> Result<(), SessionError> {
        check_pose_name(to)?;
        let (from, to) = (from.to_owned(), to.to_owned());
        self.pose_call(|reply| PoseCmd::Rename { from, to, reply })
            .await
    }

    /// Deletes pose `name`.
    pub async fn delete_pose(&self, name: &str) -> Result<(), SessionError> {
        let name = name.to_owned();
        self.pose_call(|reply| PoseCmd::Delete { name, reply })
            .await
    }

    /// Makes pose `name` the current pose, with its handle targets (and
    /// its constraint set, when the session has another one since): an
    /// undo step.
    pub async fn restore_pose(&self, name: &str) -> Result<PoseSnapshot, SessionError> {
        let name = name.to_owned();
        self.pose_call(|reply| PoseCmd::Restore { name, reply })
            .await
    }
}
