//! [`AppState`]: what every handler reaches, cheap to clone.

use std::sync::Arc;

use parking_lot::Mutex;

use crate::blocking::store_call;
use crate::cluster::Cluster;
use crate::config::Config;
use crate::error::ApiError;
use crate::metrics::Metrics;
use crate::registry::{RegistryParts, SessionRegistry};
use crate::rests::Rests;
use crate::scheduler::{Scheduler, SchedulerMetrics};
use crate::store::{MemoryStore, Store};
use crate::timed_store::timed;
use dend::deform::{FactorCache, SolveOptions};

/// Shared server state: cheap to clone (`Arc` fields).
#[derive(Clone)]
pub struct AppState {
    /// The configuration.
    pub config: Arc<Config>,
    /// Meshes and sessions storage.
    pub store: Arc<dyn Store>,
    /// The factor cache shared by all sessions.
    pub cache: Arc<FactorCache>,
    /// Prometheus metrics.
    pub metrics: Arc<Metrics>,
    /// Runs every session's solves, fairly between sessions.
    pub scheduler: Arc<Scheduler>,
    /// The live sessions: the only way to open, find or close one.
    pub registry: Arc<SessionRegistry>,
    /// Rest precomputations by mesh id, shared by that mesh's sessions.
    pub(crate) rests: Arc<Rests>,
    /// Held across an upload's `max_meshes` check and its insert, so that
    /// concurrent uploads cannot both pass the check for the last slot.
    pub(crate) mesh_admission: Arc<Mutex<()>>,
}

impl AppState {
    /// Runs `f` on the store from tokio's blocking pool
    /// ([`store_call`](crate::blocking::store_call)).
    pub(crate) async fn store_call<T, F>(&self, f: F) -> Result<T, ApiError>
    where
        F: FnOnce(&dyn Store) -> Result<T, crate::store::StoreError> + Send + 'static,
        T: Send + 'static,
    {
        store_call(&self.store, f).await
    }

    /// This instance in a shared-store deployment (None: embedded store,
    /// no leases); see `lease.rs`.
    pub fn cluster(&self) -> Option<&Arc<Cluster>> {
        self.registry.cluster()
    }

    /// State with the embedded in-memory store.
    pub fn new(config: Config) -> anyhow::Result<Self> {
        Self::with_store(config, Arc::new(MemoryStore::new()))
    }

    /// State with a given store (timed into the `dend_store_seconds`
    /// histogram). A configured shared store (`config.store`) turns
    /// session leases on.
    pub fn with_store(config: Config, store: Arc<dyn Store>) -> anyhow::Result<Self> {
        let cluster = Cluster::from_config(&config);
        Self::with_cluster(config, store, cluster)
    }

    /// State with a given store and this instance's part in a shared-store
    /// deployment (`None`: no leases), whatever the configuration says.
    pub fn with_cluster(
        config: Config,
        store: Arc<dyn Store>,
        cluster: Option<Arc<Cluster>>,
    ) -> anyhow::Result<Self> {
        let metrics = Arc::new(Metrics::new()?);
        let store: Arc<dyn Store> = Arc::new(timed(store, metrics.store_seconds.clone()));
        let scheduler = Arc::new(Scheduler::new(
            config.solver_threads,
            Some(SchedulerMetrics {
                delay: metrics.schedule_delay_seconds.clone(),
                depth: metrics.solve_queue_depth.clone(),
            }),
        ));
        let cache = Arc::new(FactorCache::with_options(
            config.factor_cache_bytes,
            SolveOptions {
                precision: config.factor_precision,
                ..SolveOptions::default()
            },
        ));
        let config = Arc::new(config);
        let rests = Arc::new(Rests::default());
        let registry = Arc::new(SessionRegistry::new(RegistryParts {
            config: config.clone(),
            store: store.clone(),
            cache: cache.clone(),
            metrics: metrics.clone(),
            scheduler: scheduler.clone(),
            rests: rests.clone(),
            cluster,
        }));
        Ok(AppState {
            config,
            store,
            cache,
            metrics,
            scheduler,
            registry,
            rests,
            mesh_admission: Arc::new(Mutex::new(())),
        })
    }
}
