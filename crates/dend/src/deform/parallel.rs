//! When an iteration's per-vertex loops run on the rayon pool.

/// Vertex count from which the per-vertex loops of an iteration (the local
/// step, the residual, STEP 2's products with `L`, the detail term's
/// loops) run on the rayon pool. From 1,536: a hierarchy's levels of
/// 2,000–4,000 vertices (below meshes of 8k–50k) run on both cores as the
/// fine mesh does, and meshes of about 1,500 vertices, which lost time to
/// the pool's hand-offs, on one (docs/performance.md, "Small levels on both
/// cores").
pub(crate) const PARALLEL_MIN_VERTICES: usize = 1536;
