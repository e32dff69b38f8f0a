//! # dend — Discrete Elastica Nonlinear Deformation of triangle meshes
//!
//! Layers, bottom-up (see `README.md` and `docs/design.md`):
//! - [`mesh`]: the validated triangle mesh, adjacency, readers/writers and
//!   the paper's procedural test shapes;
//! - [`operators`]: cotangent Laplacian, mixed Voronoi areas, curvatures
//!   (design.md §2);
//! - [`deform`]: energies, constraints, the factor cache and the DEND
//!   iteration (design.md §3–9). Pure and synchronous: no I/O, no async.
//! - [`measure`]: what the tests and the posing suite measure on a pose;
//! - [`rig`]: skinned assets' skeletons, and poses fitted back onto them
//!   as joint transforms plus a corrective shape.
//!
//! The sparse linear algebra (orderings, Cholesky, solves) is the
//! `dend-linalg` crate; the server, its store and client are `dend-server`
//! and `dend-client`. This crate has no `unsafe` code.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod deform;
pub mod measure;
pub mod mesh;
pub mod operators;
pub mod rig;
