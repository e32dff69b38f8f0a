//! Rigged assets: the skeleton of a skinned glTF asset, its joints as
//! vertex regions, and a solved pose fitted back onto the rig as joint
//! transforms plus a corrective shape.
//!
//! - [`Skeleton`] (`skeleton.rs`): the skin's joints (name, parent,
//!   head), each asset vertex's weights, and the region each joint
//!   *dominates*: the welded vertices whose largest skin weight is that
//!   joint's (ties go to the joint listed first in the skin). Constraints
//!   select regions with `{"joint": "hand.L"}` or
//!   `{"joint": "spine", "with_children": true}` (the joint's region and
//!   its descendants').
//! - [`fit`] (`fit.rs`, `pose.rs`): one rigid motion per joint, fitted to the solved
//!   pose under the asset's own weights and linear blend skinning, by
//!   alternating weighted Procrustes (`procrustes.rs`) with the joints'
//!   heads carried by their parents (bone lengths kept; only root joints
//!   translate).
//! - [`RigPose`] (`pose.rs`): the fitted motions as parent-relative TRS per
//!   joint node, and the **corrective**: per vertex, the displacement in
//!   bind space that skinning maps onto what the fit misses, so that
//!   skinning the corrected mesh with the fitted joints gives the solved
//!   pose to float precision.
//! - [`export_skeleton`] (`export.rs`): poses written as glTF, the
//!   fitted transforms in the joint nodes (or keyframes of an animation)
//!   and the correctives as morph targets.
//! - `sample.rs`: a generated rigged limb (a chain of joints) for tests.
//!
//! The skinning model is glTF's (§3.7.3): a vertex `v` (bind space, as
//! stored) is placed at `Σ_j w_j · G_j · IBM_j · v`, `G_j` the joint node's
//! global transform. The fit's unknowns are `M_j = G_j · IBM_j`, rigid
//! motions of bind space (identity: the bind pose).

mod error;
mod export;
mod fit;
mod pose;
mod procrustes;
pub mod sample;
mod skeleton;

pub use error::{describe_joints, RigError};
pub use export::{export_skeleton, PoseFit, SkeletonExport};
pub use fit::{FitOptions, Residual};
pub use pose::{fit, JointTrs, RigPose};
pub use skeleton::{Joint, JointInfo, Skeleton, SkeletonInfo};

#[cfg(test)]
mod tests;
