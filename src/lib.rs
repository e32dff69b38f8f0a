//! # dend — Discrete Elastica Nonlinear Deformation of triangle meshes
//!
//! Layers, bottom-up (see `README.md` and the design notes):
//! - [`mesh`]: the validated triangle mesh, adjacency, readers/writers and
//!   the paper's procedural test shapes;
//! - [`operators`]: cotangent Laplacian, mixed Voronoi areas, curvatures
//!   (dend.md §2);
//! - [`deform`]: energies, constraints, the factor cache and the DEND
//!   iteration (dend.md §3–6). Pure and synchronous: no I/O, no async.
//! - [`session`], [`store`], [`server`], [`client`]: the deformation
//!   server (live editing sessions, persistence seam, axum HTTP/WebSocket
//!   API) and its Rust client.
#![warn(missing_docs)]

pub mod client;
pub mod deform;
pub mod fuzzing;
pub mod measure;
pub mod mesh;
pub mod operators;
pub mod server;
pub mod session;
pub mod sparse;
pub mod store;
