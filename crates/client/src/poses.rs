//! A session's named poses: save the settled pose under a name, list,
//! read, rename, restore and delete (`/v1/sessions/{id}/poses…`).

use dend_protocol::ws::PoseInfo;
use dend_protocol::{NamedPose, PoseJson as Pose, PoseList, RenamePose, SavePose};

use crate::client::segment;
use crate::error::{check, ClientError};
use crate::session::SessionClient;

impl SessionClient {
    /// The URL of named pose `name` (percent-encoded), then `tail`.
    fn pose_url(&self, name: &str, tail: &[&str]) -> Result<reqwest::Url, ClientError> {
        let mut parts = vec!["v1", "sessions", self.id.as_str(), "poses", name];
        parts.extend_from_slice(tail);
        segment(&self.base, &parts)
    }

    /// `GET /v1/sessions/{id}/poses`: the named poses, in save order.
    pub async fn poses(&self) -> Result<Vec<PoseInfo>, ClientError> {
        let url = segment(&self.base, &["v1", "sessions", &self.id, "poses"])?;
        let r = self.http.get(url).bearer_auth(&self.token).send().await?;
        let list: PoseList = check(r).await?.json().await?;
        Ok(list.poses)
    }

    /// `POST /v1/sessions/{id}/poses`: saves the settled pose as `name`;
    /// a pose of that name is replaced only with `replace` (else
    /// `pose_exists`).
    pub async fn save_pose(&self, name: &str, replace: bool) -> Result<PoseInfo, ClientError> {
        let body = SavePose {
            name: name.to_owned(),
            replace,
        };
        Ok(self.post("/poses", Some(&body)).await?.json().await?)
    }

    /// `GET /v1/sessions/{id}/poses/{name}`: the pose with its positions.
    pub async fn named_pose(&self, name: &str) -> Result<NamedPose, ClientError> {
        let url = self.pose_url(name, &[])?;
        let r = self.http.get(url).bearer_auth(&self.token).send().await?;
        Ok(check(r).await?.json().await?)
    }

    /// `PATCH /v1/sessions/{id}/poses/{name}`: renames pose `name` to `to`.
    pub async fn rename_pose(&self, name: &str, to: &str) -> Result<PoseInfo, ClientError> {
        let body = RenamePose {
            name: to.to_owned(),
        };
        let url = self.pose_url(name, &[])?;
        let rq = self.http.patch(url).bearer_auth(&self.token).json(&body);
        Ok(check(rq.send().await?).await?.json().await?)
    }

    /// `DELETE /v1/sessions/{id}/poses/{name}`.
    pub async fn delete_pose(&self, name: &str) -> Result<(), ClientError> {
        let url = self.pose_url(name, &[])?;
        let r = self
            .http
            .delete(url)
            .bearer_auth(&self.token)
            .send()
            .await?;
        let _ = check(r).await?;
        Ok(())
    }

    /// `POST /v1/sessions/{id}/poses/{name}/restore`: the named pose
    /// becomes the current one (an undo step); returns it.
    pub async fn restore_pose(&self, name: &str) -> Result<Pose, ClientError> {
        let url = self.pose_url(name, &["restore"])?;
        let r = self.http.post(url).bearer_auth(&self.token).send().await?;
        Ok(check(r).await?.json().await?)
    }
}
