//! The scalar and point types of every mesh and geometric computation.

/// The scalar type of positions and of every geometric computation.
pub type Real = f64;

/// A 3-vector of [`Real`].
pub type Point = [Real; 3];
