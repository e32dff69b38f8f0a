//! [`MemoryStore`]: the embedded in-process store (nothing survives a
//! restart; a crash-safe backend implements the same trait).

use std::collections::HashMap;
use std::sync::Arc;

use parking_lot::Mutex;

use super::{Checkpoint, JournalEntry, SessionRecord, Store, StoreError, StoredAsset};
use dend::mesh::Mesh;

#[derive(Default)]
struct SessionData {
    record: Option<SessionRecord>,
    journal: Vec<JournalEntry>,
    checkpoint: Option<Checkpoint>,
}

/// An in-memory [`Store`]: hash maps behind mutexes.
#[derive(Default)]
pub struct MemoryStore {
    meshes: Mutex<HashMap<String, Arc<Mesh>>>,
    assets: Mutex<HashMap<String, StoredAsset>>,
    sessions: Mutex<HashMap<String, SessionData>>,
}

impl MemoryStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }
}

fn missing(id: &str) -> StoreError {
    StoreError::Backend(format!("no session `{id}`"))
}

impl Store for MemoryStore {
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError> {
        let _ = self.meshes.lock().insert(id.to_owned(), mesh);
        Ok(())
    }

    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError> {
        Ok(self.meshes.lock().get(id).cloned())
    }

    fn mesh_count(&self) -> Result<usize, StoreError> {
        Ok(self.meshes.lock().len())
    }

    fn put_asset(&self, id: &str, asset: &StoredAsset) -> Result<(), StoreError> {
        let _ = self.assets.lock().insert(id.to_owned(), asset.clone());
        Ok(())
    }

    fn get_asset(&self, id: &str) -> Result<Option<StoredAsset>, StoreError> {
        Ok(self.assets.lock().get(id).cloned())
    }

    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        let _ = self.assets.lock().remove(id);
        Ok(self.meshes.lock().remove(id).is_some())
    }

    fn put_session(&self, record: &SessionRecord) -> Result<(), StoreError> {
        self.sessions
            .lock()
            .entry(record.id.clone())
            .or_default()
            .record = Some(record.clone());
        Ok(())
    }

    fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError> {
        Ok(self.sessions.lock().get(id).and_then(|s| s.record.clone()))
    }

    fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError> {
        Ok(self
            .sessions
            .lock()
            .values()
            .filter_map(|s| s.record.clone())
            .collect())
    }

    fn delete_session(&self, id: &str) -> Result<(), StoreError> {
        let _ = self.sessions.lock().remove(id);
        Ok(())
    }

    fn set_constraints(&self, id: &str, spec: &serde_json::Value) -> Result<(), StoreError> {
        let mut sessions = self.sessions.lock();
        let s = sessions.get_mut(id).ok_or_else(|| missing(id))?;
        let record = s.record.as_mut().ok_or_else(|| missing(id))?;
        record.constraints = Some(spec.clone());
        s.journal.clear();
        s.checkpoint = None;
        Ok(())
    }

    fn append(&self, id: &str, entries: &[JournalEntry]) -> Result<(), StoreError> {
        let mut sessions = self.sessions.lock();
        let s = sessions.get_mut(id).ok_or_else(|| missing(id))?;
        s.journal.extend_from_slice(entries);
        Ok(())
    }

    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError> {
        Ok(self
            .sessions
            .lock()
            .get(id)
            .map(|s| s.journal.clone())
            .unwrap_or_default())
    }

    fn checkpoint(&self, id: &str, checkpoint: &Checkpoint) -> Result<(), StoreError> {
        let mut sessions = self.sessions.lock();
        let s = sessions.get_mut(id).ok_or_else(|| missing(id))?;
        s.checkpoint = Some(checkpoint.clone());
        s.journal.clear();
        Ok(())
    }

    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        Ok(self
            .sessions
            .lock()
            .get(id)
            .and_then(|s| s.checkpoint.clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(id: &str) -> SessionRecord {
        SessionRecord {
            id: id.into(),
            mesh_id: "m".into(),
            token_sha256: "00".into(),
            params: serde_json::json!({}),
            constraints: None,
            created_unix: 0,
        }
    }

    #[test]
    fn journal_is_truncated_by_checkpoint_and_constraints() -> Result<(), StoreError> {
        let s = MemoryStore::new();
        s.put_session(&record("a"))?;
        let drag = JournalEntry::Drag {
            handle: 0,
            rotation: [0.0, 0.0, 0.0, 1.0],
            translation: [1.0, 0.0, 0.0],
            seq: 1,
        };
        s.append("a", &[drag.clone(), drag.clone()])?;
        assert_eq!(s.journal("a")?, vec![drag.clone(), drag.clone()]);
        let cp = Checkpoint {
            revision: 3,
            ack_seq: 2,
            pose: vec![[0.0; 3]],
            targets: vec![],
        };
        s.checkpoint("a", &cp)?;
        assert!(s.journal("a")?.is_empty());
        assert_eq!(s.get_checkpoint("a")?, Some(cp));
        s.append("a", &[drag])?;
        s.set_constraints("a", &serde_json::json!({"fixed": [0]}))?;
        assert!(s.journal("a")?.is_empty());
        assert!(s.get_checkpoint("a")?.is_none());
        assert!(s.get_session("a")?.unwrap().constraints.is_some());
        s.delete_session("a")?;
        assert!(s.get_session("a")?.is_none());
        assert!(s.append("a", &[]).is_err());
        Ok(())
    }
}
