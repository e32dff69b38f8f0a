//! The rest-mesh precomputation ([`Rest`]): operators, STEP 1 and the
//! Procrustes weights, computed once per mesh and shared by its sessions.

use std::borrow::Cow;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use sprs::CsMat;

use super::constraints::Constraints;
use super::detail::{Mu, RingWeights};
use super::elastic::ElasticOps;
use super::energy::Energy;
use super::error::DeformError;
use super::params::{ElasticParams, Mode, Params};
use crate::mesh::order::VertexOrder;
use crate::mesh::{Mesh, Point, Real};
use crate::operators::Operators;

static NEXT_REST_ID: AtomicU64 = AtomicU64::new(1);

/// Everything computed once per rest mesh: the operators (design.md §2),
/// and on first use STEP 1 `μ` of each mode (§6.1), the Procrustes
/// weights, the energies, the elastic operators and the coarse levels.
/// Share as `Arc<Rest>`.
#[derive(Debug)]
pub struct Rest {
    id: u64,
    /// The mesh in the solver's vertex order (`order`): every operator,
    /// factor and internal pose is indexed by it.
    pub(super) mesh: Mesh,
    /// The mesh as given and the solver's order of it, when the solver
    /// renumbered it for locality ([`VertexOrder::for_locality`]):
    /// constraints and poses cross the API in the given order.
    order: Option<(Mesh, VertexOrder)>,
    pub(super) ops: Operators,
    /// STEP 1 (§6.1) of the least-squares formulations, each mode's built
    /// on first use: the default elastic formulation never uses them.
    mu_default: std::sync::OnceLock<Mu>,
    mu_paper: std::sync::OnceLock<Mu>,
    /// The Procrustes weights of the least-squares formulations' local
    /// rotations, built on first use ([`Rest::weights`]).
    weights: std::sync::OnceLock<RingWeights>,
    active: Vec<bool>,
    /// The energy matrices built so far (most recent last), at most
    /// [`ENERGY_CACHE`]: every constraint set of a session reuses its
    /// energy's.
    energies: Mutex<Vec<(Energy, Arc<EnergyOperator>)>>,
    /// The elastic formulation's operators built so far, by weights (most
    /// recent last), at most [`ENERGY_CACHE`].
    elastics: Mutex<Vec<(ElasticKey, Arc<ElasticOps>)>>,
    /// The coarse levels of the elastic solver (`deform::coarse`) by
    /// simplification ratio (`None`: the mesh has none), built on first
    /// use, at most [`ENERGY_CACHE`].
    pub(super) coarse: Mutex<Vec<(usize, Option<Arc<CoarseLevel>>)>>,
}

/// How [`Rest::with_ordering`] numbers the solver's vertices.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum VertexOrdering {
    /// Breadth-first where the mesh is large and its own order scattered
    /// ([`VertexOrder::for_locality`]), else the mesh's own.
    #[default]
    Auto,
    /// The mesh's own order.
    AsGiven,
    /// Breadth-first ([`VertexOrder::breadth_first`]) whatever the mesh.
    BreadthFirst,
}

/// What an [`ElasticOps`] depends on besides the rest mesh.
type ElasticKey = (bool, u64, u64, u64, u64, u64);

/// Energy matrices a [`Rest`] keeps (sessions rarely switch energies).
const ENERGY_CACHE: usize = 4;

/// An energy's matrix `A` (design.md §3) and its rest-state image `A X`:
/// they depend on the rest mesh and the energy only, not on the
/// constraint set.
#[derive(Debug)]
pub(crate) struct EnergyOperator {
    pub a: CsMat<Real>,
    pub ax: Vec<Point>,
}

/// A rest mesh's coarse level (built by `deform::coarse`, kept by its
/// [`Rest`]): the coarse rest state and the maps between the levels.
#[derive(Debug)]
pub struct CoarseLevel {
    /// The coarse rest state (with coarse levels of its own in a
    /// hierarchy).
    pub rest: Arc<Rest>,
    /// Fine (solver) index of each coarse vertex, `#Vc`: increasing unless
    /// the fine mesh was renumbered (the coarse mesh keeps the mesh's own
    /// order).
    pub fine_of: Vec<u32>,
    /// Coarse index of each fine vertex, `u32::MAX` if it is not one, `#V`.
    pub coarse_of: Vec<u32>,
    /// The coarse vertex nearest to each fine vertex along the fine edges
    /// (`u32::MAX` for unreferenced vertices), `#V`.
    pub near: Vec<u32>,
}

impl Rest {
    /// Builds the operators on `mesh` (STEP 1 and the Procrustes weights
    /// wait for a least-squares solve), in a vertex order with locality
    /// where the mesh's own has none ([`VertexOrdering::Auto`]). O(#F).
    pub fn new(mesh: Mesh) -> Result<Rest, DeformError> {
        Rest::with_ordering(mesh, VertexOrdering::Auto)
    }

    /// [`Rest::new`] with the solver's vertex order chosen.
    pub fn with_ordering(mesh: Mesh, ordering: VertexOrdering) -> Result<Rest, DeformError> {
        let order = match ordering {
            VertexOrdering::Auto => VertexOrder::for_locality(&mesh),
            VertexOrdering::AsGiven => None,
            VertexOrdering::BreadthFirst => Some(VertexOrder::breadth_first(&mesh)),
        };
        let (mesh, order) = match order {
            Some(o) => (o.renumber(&mesh), Some((mesh, o))),
            None => (mesh, None),
        };
        let ops = Operators::new(&mesh);
        if !(ops.scale.is_finite() && ops.scale > 0.0) {
            return Err(DeformError::NonFinite {
                what: "mean edge length",
            });
        }
        let topo = mesh.topology();
        let active = (0..mesh.num_vertices())
            .map(|v| !topo.ring(v).is_empty())
            .collect();
        Ok(Rest {
            id: NEXT_REST_ID.fetch_add(1, Ordering::Relaxed),
            mesh,
            order,
            ops,
            mu_default: std::sync::OnceLock::new(),
            mu_paper: std::sync::OnceLock::new(),
            weights: std::sync::OnceLock::new(),
            active,
            energies: Mutex::new(Vec::new()),
            elastics: Mutex::new(Vec::new()),
            coarse: Mutex::new(Vec::new()),
        })
    }

    /// [`Rest::new`] for a coarse level's own rest state: in the coarse
    /// mesh's own order (its vertices keep the fine mesh's), with coarse
    /// levels of its own for a hierarchy ([`Levels::Many`]).
    ///
    /// [`Levels::Many`]: crate::deform::Levels::Many
    pub(super) fn coarse_level(mesh: Mesh) -> Result<Rest, DeformError> {
        Rest::with_ordering(mesh, VertexOrdering::AsGiven)
    }

    /// A process-unique id (factor cache keys refer to it).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The rest mesh (mesh units), in its own vertex order: the order of
    /// constraints and poses at the API.
    pub fn mesh(&self) -> &Mesh {
        self.order.as_ref().map_or(&self.mesh, |(m, _)| m)
    }

    /// The solver's vertex order, when it renumbered the mesh
    /// ([`Rest::with_ordering`]); `None`: the mesh's own order.
    pub fn vertex_order(&self) -> Option<&VertexOrder> {
        self.order.as_ref().map(|(_, o)| o)
    }

    /// `constraints` (indices of [`Rest::mesh`]) in the solver's order:
    /// the same set, its index lists mapped and sorted again.
    pub(crate) fn internal_constraints<'a>(
        &self,
        constraints: &'a Constraints,
    ) -> Cow<'a, Constraints> {
        let Some(order) = self.vertex_order() else {
            return Cow::Borrowed(constraints);
        };
        let mut c = constraints.clone();
        let mut fixed: Vec<(u32, Point)> = c
            .fixed
            .iter()
            .zip(&c.fixed_at)
            .map(|(&v, &p)| (order.internal(v), p))
            .collect();
        fixed.sort_unstable_by_key(|&(v, _)| v);
        (c.fixed, c.fixed_at) = fixed.into_iter().unzip();
        for h in &mut c.handles {
            let mut vb: Vec<(u32, Point)> = h
                .vertices
                .iter()
                .zip(&h.base)
                .map(|(&v, &p)| (order.internal(v), p))
                .collect();
            vb.sort_unstable_by_key(|&(v, _)| v);
            (h.vertices, h.base) = vb.into_iter().unzip();
        }
        Cow::Owned(c)
    }

    /// The rest operators (normalised copy), in the solver's vertex order
    /// ([`Rest::vertex_order`]).
    pub fn operators(&self) -> &Operators {
        &self.ops
    }

    /// Whether each vertex is referenced by a triangle (the solver's
    /// order).
    pub fn active(&self) -> &[bool] {
        &self.active
    }

    /// `energy`'s matrix and `A X`, built on first use and kept.
    pub(crate) fn energy(&self, energy: Energy) -> Arc<EnergyOperator> {
        cached(&self.energies, energy, || {
            let a = energy.matrix(&self.ops);
            let ax = crate::operators::laplacian_coordinates(&a, &self.ops.positions);
            Arc::new(EnergyOperator { a, ax })
        })
    }

    /// The elastic formulation's operators for `params`' weights, built on
    /// first use and kept.
    pub(crate) fn elastic(&self, params: &Params, weights: &ElasticParams) -> Arc<ElasticOps> {
        let key: ElasticKey = (
            params.energy == Energy::ThinPlate,
            weights.stretch.to_bits(),
            weights.bending.to_bits(),
            params.lambda2.to_bits(),
            weights.area.to_bits(),
            weights.laplacian.to_bits(),
        );
        cached(&self.elastics, key, || {
            Arc::new(ElasticOps::new(&self.mesh, &self.ops, params, weights))
        })
    }

    pub(super) fn mu(&self, mode: Mode) -> &Mu {
        let cell = match mode {
            Mode::Default => &self.mu_default,
            Mode::Paper => &self.mu_paper,
        };
        cell.get_or_init(|| {
            Mu::new(
                mode,
                self.mesh.topology(),
                &self.ops.positions,
                &self.ops.delta,
            )
        })
    }

    /// The Procrustes weights of the least-squares local rotations.
    pub(super) fn weights(&self) -> &RingWeights {
        self.weights
            .get_or_init(|| RingWeights::new(self.mesh.topology(), &self.ops.lbar))
    }
}

/// The value of `key` in a small most-recent-last cache of at most
/// [`ENERGY_CACHE`] entries, built by `build` (outside the lock) when
/// missing; a value another thread stored meanwhile wins. Values are
/// cheap clones (`Arc`s).
pub(super) fn cached<K: PartialEq + Copy, V: Clone>(
    cache: &Mutex<Vec<(K, V)>>,
    key: K,
    build: impl FnOnce() -> V,
) -> V {
    let find = |v: &[(K, V)]| v.iter().find(|(k, _)| *k == key).map(|(_, op)| op.clone());
    if let Some(op) = cache.lock().ok().and_then(|v| find(&v)) {
        return op;
    }
    let op = build();
    if let Ok(mut v) = cache.lock() {
        if let Some(found) = find(&v) {
            return found;
        }
        if v.len() == ENERGY_CACHE {
            v.remove(0);
        }
        v.push((key, op.clone()));
    }
    op
}
