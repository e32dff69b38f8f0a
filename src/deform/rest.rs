//! The rest-mesh precomputation ([`Rest`]): operators, STEP 1 and the
//! Procrustes weights, computed once per mesh and shared by its sessions.

use std::sync::atomic::{AtomicU64, Ordering};

use super::detail::{Mu, RingWeights};
use super::params::Mode;
use super::DeformError;
use crate::mesh::Mesh;
use crate::operators::Operators;

static NEXT_REST_ID: AtomicU64 = AtomicU64::new(1);

/// Everything computed once per rest mesh: the operators (dend.md §2), STEP 1
/// `μ` for both modes (§5) and the Procrustes weights. Share as `Arc<Rest>`.
#[derive(Debug)]
pub struct Rest {
    id: u64,
    pub(super) mesh: Mesh,
    pub(super) ops: Operators,
    mu_default: Mu,
    /// STEP 1 of the literal paper, built on first use (most sessions never
    /// use it).
    mu_paper: std::sync::OnceLock<Mu>,
    pub(super) weights: RingWeights,
    active: Vec<bool>,
}

impl Rest {
    /// Builds the operators and STEP 1 on `mesh`. O(#F).
    pub fn new(mesh: Mesh) -> Result<Rest, DeformError> {
        let ops = Operators::new(&mesh);
        if !(ops.scale.is_finite() && ops.scale > 0.0) {
            return Err(DeformError::NonFinite {
                what: "mean edge length",
            });
        }
        let topo = mesh.topology();
        let mu_default = Mu::new(Mode::Default, topo, &ops.positions, &ops.delta);
        let weights = RingWeights::new(topo, &ops.lbar);
        let active = (0..mesh.num_vertices())
            .map(|v| !topo.ring(v).is_empty())
            .collect();
        Ok(Rest {
            id: NEXT_REST_ID.fetch_add(1, Ordering::Relaxed),
            mesh,
            ops,
            mu_default,
            mu_paper: std::sync::OnceLock::new(),
            weights,
            active,
        })
    }

    /// A process-unique id (factor cache keys refer to it).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The rest mesh (mesh units).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The rest operators (normalised copy).
    pub fn operators(&self) -> &Operators {
        &self.ops
    }

    /// Whether each vertex is referenced by a triangle.
    pub fn active(&self) -> &[bool] {
        &self.active
    }

    pub(super) fn mu(&self, mode: Mode) -> &Mu {
        match mode {
            Mode::Default => &self.mu_default,
            Mode::Paper => self.mu_paper.get_or_init(|| {
                Mu::new(
                    Mode::Paper,
                    self.mesh.topology(),
                    &self.ops.positions,
                    &self.ops.delta,
                )
            }),
        }
    }
}
