//! Procedural generators of the paper's test shapes.
