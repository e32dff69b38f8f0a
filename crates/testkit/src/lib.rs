//! The one test kit of the workspace, used by every integration test,
//! bench and example of the root package and by `dend-server`'s unit tests.
//!
//! - [`shapes`]: small analytic and generated meshes (the library's own
//!   generators, `dend::mesh::gen`, where it has the shape).
//! - [`shared`]: the public meshes folder (`$DEND_MESHES`, default
//!   `../shared/meshes` beside the repository), the skip log
//!   ([`record_skip`]) and the Python oracle.
//! - [`solve`]: the solver tests' constraint set-ups, solve and distance.
//! - [`gltf_validator`]: the Khronos glTF-Validator, run with Node.js.
//! - `server` (feature `server`): an in-process server on port 0.
//!
//! Mesh files are read and written by the library (`dend::mesh::io`); the
//! kit has no parser of its own.

pub mod assets;
pub mod gltf_validator;
#[cfg(feature = "server")]
pub mod server;
pub mod shapes;
pub mod shared;
pub mod solve;

pub use shapes::*;
pub use shared::*;
pub use solve::*;
