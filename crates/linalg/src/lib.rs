//! # dend-linalg — the sparse linear algebra under dend
//!
//! What the DEND solver's factor cache needs, apart from the geometry:
//! - [`sparse`]: Gustavson sparse products with the pattern computed once
//!   and the values many times, diagonal scaling and shifts;
//! - [`ordering`]: fill-reducing orderings (faer's AMD, METIS nested
//!   dissection);
//! - [`cholesky`]: symbolic analysis (faer's) and numeric factorisation
//!   ([`numeric`]: dend's tree-parallel supernodal Cholesky in faer's
//!   layout);
//! - [`trisolve`]: the supernodal triangular solves for a few right-hand
//!   sides;
//! - [`cg`]: Jacobi-preconditioned conjugate gradients, the fallback for
//!   systems whose factor does not fit;
//! - [`cpu`]: CPU feature detection shared by every kernel.
//!
//! Every `unsafe` block of the project lives in this crate, each with a
//! `SAFETY` comment; the property tests against faer's own factorisation
//! live beside the kernels.
#![warn(missing_docs)]

pub mod cg;
pub mod cholesky;
pub mod cpu;
pub mod numeric;
pub mod ordering;
pub mod sparse;
pub mod trisolve;

#[cfg(test)]
mod test_util;

/// The scalar of every matrix and vector.
pub type Real = f64;

/// Why a factorisation could not be computed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LinalgError {
    /// The matrix is not (numerically) positive definite.
    #[error("the matrix is not positive definite (pivot {pivot})")]
    NotPositiveDefinite {
        /// The failing pivot, in the permuted order.
        pivot: usize,
    },
    /// An allocation failed.
    #[error("out of memory during {what}")]
    OutOfMemory {
        /// The stage.
        what: &'static str,
    },
}
