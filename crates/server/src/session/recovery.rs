//! Re-deriving a session's editing state from the store: the last
//! [`Checkpoint`] plus every journaled drag after it.
//!
//! The handle targets are rebuilt exactly as the actor built them: the
//! checkpoint's targets (or the spec's initial ones when there is no
//! checkpoint yet), then each journaled delta composed in order with
//! [`RigidTransform::then`], from the same stored quaternion components, so
//! the recovered targets equal the live ones bit for bit.

use nalgebra::{Quaternion, UnitQuaternion};

use crate::store::{Checkpoint, JournalEntry, StoreError, StoredTransform};
use dend::deform::{Constraints, RigidTransform};

/// What the store holds of a session's edits since its constraints were set.
#[derive(Debug, Clone, Default)]
pub struct Recovered {
    /// The last checkpoint, if any.
    pub checkpoint: Option<Checkpoint>,
    /// Journal entries after it, oldest first.
    pub journal: Vec<JournalEntry>,
    /// The highest client sequence number included (checkpoint or journal).
    pub ack_seq: u64,
}

fn corrupt(reason: String) -> StoreError {
    StoreError::Corrupt {
        what: "recovered session state".into(),
        reason,
    }
}

/// A stored `[x, y, z, w]` quaternion, which must be unit (±1e-9).
fn unit(q: [f64; 4]) -> Result<UnitQuaternion<f64>, StoreError> {
    let q = Quaternion::new(q[3], q[0], q[1], q[2]);
    if !q.coords.iter().all(|x| x.is_finite()) || (q.norm() - 1.0).abs() > 1e-9 {
        return Err(corrupt(format!("rotation {q:?} is not a unit quaternion")));
    }
    Ok(UnitQuaternion::new_unchecked(q))
}

/// A [`StoredTransform`] back as a [`RigidTransform`].
pub fn transform(t: &StoredTransform) -> Result<RigidTransform, StoreError> {
    Ok(RigidTransform {
        rotation: unit(t.rotation)?,
        translation: t.translation,
        pivot: t.pivot,
    })
}

impl Recovered {
    /// The state from what the store holds: the last checkpoint and the
    /// journal after it; `ack_seq` is the highest sequence number either
    /// includes.
    pub fn new(checkpoint: Option<Checkpoint>, journal: Vec<JournalEntry>) -> Self {
        let journaled_seq = journal
            .iter()
            .map(|JournalEntry::Drag { seq, .. }| *seq)
            .max()
            .unwrap_or(0);
        Recovered {
            ack_seq: checkpoint
                .as_ref()
                .map_or(0, |c| c.ack_seq)
                .max(journaled_seq),
            checkpoint,
            journal,
        }
    }

    /// Sets `constraints`' handle targets to the recovered ones (checkpoint
    /// targets, then the journal's deltas); a count or index that does not
    /// fit the constraints is [`StoreError::Corrupt`].
    pub fn apply(&self, constraints: &mut Constraints) -> Result<(), StoreError> {
        let handles = &mut constraints.handles;
        if let Some(cp) = &self.checkpoint {
            if cp.targets.len() != handles.len() {
                return Err(corrupt(format!(
                    "{} stored targets for {} handles",
                    cp.targets.len(),
                    handles.len()
                )));
            }
            for (h, t) in handles.iter_mut().zip(&cp.targets) {
                h.target = transform(t)?;
            }
        }
        for (k, e) in self.journal.iter().enumerate() {
            let JournalEntry::Drag {
                handle,
                rotation,
                translation,
                ..
            } = e;
            let n = handles.len();
            let h = handles.get_mut(*handle).ok_or_else(|| {
                corrupt(format!("journal entry {k} names handle {handle} of {n}"))
            })?;
            h.target = h.target.then(unit(*rotation)?, *translation);
        }
        Ok(())
    }

    /// The checkpoint pose when it fits `vertices` vertices and is finite.
    pub fn pose(&self, vertices: usize) -> Option<Vec<[f64; 3]>> {
        let cp = self.checkpoint.as_ref()?;
        let ok = cp.pose.len() == vertices && cp.pose.iter().flatten().all(|x| x.is_finite());
        ok.then(|| cp.pose.clone())
    }
}
