//! Mesh readers and writers.
