//! The rest precomputations of the meshes in use, shared by their sessions.

use std::collections::HashMap;
use std::sync::{Arc, Weak};

use parking_lot::Mutex;

use crate::blocking::store_call;
use crate::error::ApiError;
use crate::store::Store;
use dend::deform::{FactorCache, Rest};

/// Rest precomputations by mesh id, alive while a session uses them.
#[derive(Default)]
pub struct Rests {
    /// Rest precomputations by mesh id, shared by that mesh's sessions.
    by_mesh: Mutex<HashMap<String, Weak<Rest>>>,
    /// Ids of every rest built per mesh id (factors are cached by rest id):
    /// deleting a mesh evicts their factors.
    ids: Mutex<HashMap<String, Vec<u64>>>,
}

impl Rests {
    /// Rest precomputation of mesh `mesh_id` (read from `store`), shared
    /// while any session uses it.
    pub(crate) async fn get(
        &self,
        store: &Arc<dyn Store>,
        mesh_id: &str,
    ) -> Result<Arc<Rest>, ApiError> {
        if let Some(r) = self.by_mesh.lock().get(mesh_id).and_then(Weak::upgrade) {
            return Ok(r);
        }
        let id = mesh_id.to_owned();
        let mesh = store_call(store, move |s| s.get_mesh(&id))
            .await?
            .ok_or_else(|| ApiError::MeshNotFound(mesh_id.to_owned()))?;
        let rest = tokio::task::spawn_blocking(move || Rest::new((*mesh).clone()))
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))??;
        let rest = Arc::new(rest);
        {
            // the elastic solver's coarse level, off the first settle's path
            let rest = rest.clone();
            tokio::task::spawn_blocking(move || rest.prepare_coarse_level());
        }
        let mut rests = self.by_mesh.lock();
        // Sessions created together may have built it concurrently: keep the
        // first one, so that they share its id and hence their factors.
        if let Some(r) = rests.get(mesh_id).and_then(Weak::upgrade) {
            return Ok(r);
        }
        rests.retain(|_, w| w.strong_count() > 0);
        let _ = rests.insert(mesh_id.to_owned(), Arc::downgrade(&rest));
        self.ids
            .lock()
            .entry(mesh_id.to_owned())
            .or_default()
            .push(rest.id());
        Ok(rest)
    }

    /// Forgets mesh `mesh_id`'s rest precomputations and evicts their cached
    /// factors ([`FactorCache::evict_rest`]); returns how many rests it had.
    pub(crate) fn evict(&self, cache: &FactorCache, mesh_id: &str) -> usize {
        let _ = self.by_mesh.lock().remove(mesh_id);
        let ids = self.ids.lock().remove(mesh_id).unwrap_or_default();
        for &id in &ids {
            cache.evict_rest(id);
        }
        ids.len()
    }
}
