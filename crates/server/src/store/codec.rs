//! The compact binary encodings both database stores use, little-endian:
//! points as `f64` triples (bit-exact), triangles as `u32` triples, targets
//! as 10 `f64` each (quaternion, translation, pivot), journal entries as
//! one fixed 73-byte record (see [`encode_entry`]). Every decode failure is
//! a [`StoreError::Corrupt`] naming the record.

use crate::store::types::{Checkpoint, JournalEntry, SessionRecord, StoreError, StoredTransform};

pub(super) fn corrupt(what: impl Into<String>, reason: impl Into<String>) -> StoreError {
    StoreError::Corrupt {
        what: what.into(),
        reason: reason.into(),
    }
}

fn put_f64s(out: &mut Vec<u8>, xs: &[f64]) {
    for x in xs {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// Splits `blob` into `stride`-byte records, or says why it cannot.
fn records<'a>(
    blob: &'a [u8],
    stride: usize,
    what: &str,
) -> Result<std::slice::ChunksExact<'a, u8>, StoreError> {
    if blob.len() % stride != 0 {
        return Err(corrupt(
            what,
            format!("blob of {} bytes is not a multiple of {stride}", blob.len()),
        ));
    }
    Ok(blob.chunks_exact(stride))
}

fn f64_at(b: &[u8], i: usize) -> f64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[8 * i..8 * i + 8]);
    f64::from_le_bytes(a)
}

fn f64_array<const N: usize>(b: &[u8], start: usize) -> [f64; N] {
    std::array::from_fn(|k| f64_at(b, start + k))
}

pub(super) fn encode_points(p: &[[f64; 3]]) -> Vec<u8> {
    let mut out = Vec::with_capacity(p.len() * 24);
    for v in p {
        put_f64s(&mut out, v);
    }
    out
}

pub(super) fn decode_points(b: &[u8], what: &str) -> Result<Vec<[f64; 3]>, StoreError> {
    Ok(records(b, 24, what)?
        .map(|r| f64_array::<3>(r, 0))
        .collect())
}

pub(super) fn encode_triangles(t: &[[u32; 3]]) -> Vec<u8> {
    let mut out = Vec::with_capacity(t.len() * 12);
    for f in t {
        for i in f {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}

pub(super) fn decode_triangles(b: &[u8], what: &str) -> Result<Vec<[u32; 3]>, StoreError> {
    Ok(records(b, 12, what)?
        .map(|r| {
            std::array::from_fn(|k| {
                u32::from_le_bytes([r[4 * k], r[4 * k + 1], r[4 * k + 2], r[4 * k + 3]])
            })
        })
        .collect())
}

pub(super) fn encode_targets(t: &[StoredTransform]) -> Vec<u8> {
    let mut out = Vec::with_capacity(t.len() * 80);
    for x in t {
        put_f64s(&mut out, &x.rotation);
        put_f64s(&mut out, &x.translation);
        put_f64s(&mut out, &x.pivot);
    }
    out
}

pub(super) fn decode_targets(b: &[u8], what: &str) -> Result<Vec<StoredTransform>, StoreError> {
    Ok(records(b, 80, what)?
        .map(|r| StoredTransform {
            rotation: f64_array(r, 0),
            translation: f64_array(r, 4),
            pivot: f64_array(r, 7),
        })
        .collect())
}

/// Tag byte of a [`JournalEntry::Drag`] record.
const TAG_DRAG: u8 = 1;
/// Size of an encoded journal entry: tag, handle `u64`, rotation 4×`f64`,
/// translation 3×`f64`, seq `u64`.
pub(super) const ENTRY_BYTES: usize = 1 + 8 + 32 + 24 + 8;

/// Encodes a journal entry as a fixed-size little-endian record.
pub fn encode_entry(e: &JournalEntry) -> Vec<u8> {
    let mut out = Vec::with_capacity(ENTRY_BYTES);
    match e {
        JournalEntry::Drag {
            handle,
            rotation,
            translation,
            seq,
        } => {
            out.push(TAG_DRAG);
            out.extend_from_slice(&(*handle as u64).to_le_bytes());
            put_f64s(&mut out, rotation);
            put_f64s(&mut out, translation);
            out.extend_from_slice(&seq.to_le_bytes());
        }
    }
    out
}

/// Decodes a record written by [`encode_entry`]; `what` names it in errors.
pub fn decode_entry(b: &[u8], what: &str) -> Result<JournalEntry, StoreError> {
    if b.len() != ENTRY_BYTES {
        return Err(corrupt(
            what,
            format!("{} bytes, expected {ENTRY_BYTES}", b.len()),
        ));
    }
    if b[0] != TAG_DRAG {
        return Err(corrupt(what, format!("unknown entry tag {}", b[0])));
    }
    let u64_at = |o: usize| {
        let mut a = [0u8; 8];
        a.copy_from_slice(&b[o..o + 8]);
        u64::from_le_bytes(a)
    };
    let handle =
        usize::try_from(u64_at(1)).map_err(|_| corrupt(what, "handle index out of range"))?;
    let body = &b[9..9 + 56];
    let rotation: [f64; 4] = f64_array(body, 0);
    let translation: [f64; 3] = f64_array(body, 4);
    if !rotation.iter().chain(&translation).all(|x| x.is_finite()) {
        return Err(corrupt(what, "non-finite delta"));
    }
    Ok(JournalEntry::Drag {
        handle,
        rotation,
        translation,
        seq: u64_at(65),
    })
}

/// The columns of a session record, in the order [`SELECT_SESSION`] reads
/// them (the `sessions` table of both SQL backends).
pub(super) const SELECT_SESSION: &str =
    "SELECT id, mesh_id, token_sha256, params, constraints, created_unix FROM sessions";

/// A session record as stored: the row shape of the SQL backends' `sessions`
/// table (fields in [`SELECT_SESSION`]'s order), checked on the way in and
/// out.
pub(super) struct RecordRow {
    pub id: String,
    pub mesh_id: String,
    /// The token hash's 32 raw bytes.
    pub token_sha256: Vec<u8>,
    /// The parameters' JSON.
    pub params: String,
    /// The constraint set's JSON.
    pub constraints: Option<String>,
    pub created_unix: i64,
}

impl RecordRow {
    /// The row of `r`; a token hash that is not 64 hex digits is refused
    /// ([`token_hash_bytes`]).
    pub(super) fn encode(r: &SessionRecord) -> Result<RecordRow, StoreError> {
        Ok(RecordRow {
            id: r.id.clone(),
            mesh_id: r.mesh_id.clone(),
            token_sha256: token_hash_bytes(r)?,
            params: r.params.to_string(),
            constraints: r.constraints.as_ref().map(|c| c.to_string()),
            created_unix: i64::try_from(r.created_unix).unwrap_or(i64::MAX),
        })
    }

    /// The record of a stored row (a row that cannot be one is corrupt).
    pub(super) fn decode(self) -> Result<SessionRecord, StoreError> {
        let RecordRow {
            id,
            mesh_id,
            token_sha256: hash,
            params,
            constraints,
            created_unix: created,
        } = self;
        let what = || format!("session `{id}`");
        if hash.len() != 32 {
            return Err(corrupt(
                what(),
                format!("token hash of {} bytes, expected 32", hash.len()),
            ));
        }
        let params =
            serde_json::from_str(&params).map_err(|e| corrupt(what(), format!("params: {e}")))?;
        let constraints = match constraints {
            Some(c) => Some(
                serde_json::from_str(&c)
                    .map_err(|e| corrupt(what(), format!("constraints: {e}")))?,
            ),
            None => None,
        };
        let created_unix =
            u64::try_from(created).map_err(|_| corrupt(what(), "negative creation time"))?;
        Ok(SessionRecord {
            id,
            mesh_id,
            token_sha256: hex::encode(hash),
            params,
            constraints,
            created_unix,
        })
    }
}

/// A checkpoint from its stored columns (`ack_seq` holds the `u64`'s bits).
pub(super) fn decode_checkpoint(
    revision: i64,
    ack_seq: i64,
    pose: &[u8],
    targets: &[u8],
    id: &str,
) -> Result<Checkpoint, StoreError> {
    let what = format!("checkpoint of session `{id}`");
    let revision = u64::try_from(revision).map_err(|_| corrupt(&what, "negative revision"))?;
    let pose = decode_points(pose, &what)?;
    if !pose.iter().flatten().all(|x| x.is_finite()) {
        return Err(corrupt(&what, "non-finite pose coordinate"));
    }
    let targets = decode_targets(targets, &what)?;
    let finite = targets.iter().all(|t| {
        t.rotation
            .iter()
            .chain(&t.translation)
            .chain(&t.pivot)
            .all(|x| x.is_finite())
    });
    if !finite {
        return Err(corrupt(&what, "non-finite target"));
    }
    Ok(Checkpoint {
        revision,
        ack_seq: ack_seq as u64,
        pose,
        targets,
    })
}

/// The 32 raw bytes of a record's token hash; anything but 64 hex digits is
/// refused (a store never keeps what could be a token).
fn token_hash_bytes(r: &SessionRecord) -> Result<Vec<u8>, StoreError> {
    hex::decode(&r.token_sha256)
        .ok()
        .filter(|h| h.len() == 32)
        .ok_or_else(|| {
            StoreError::Backend(format!(
                "session `{}`: token hash is not 64 hex digits",
                r.id
            ))
        })
}

/// A named pose as stored: the row shape of the SQL backends'
/// `named_poses` table (fields in [`SELECT_NAMED_POSE`]'s order).
pub(super) struct NamedPoseRow {
    pub name: String,
    pub ordinal: i64,
    pub revision: i64,
    pub created_unix: i64,
    /// The constraint set's JSON.
    pub constraints: Option<String>,
    /// [`encode_points`] of the pose.
    pub pose: Vec<u8>,
    /// [`encode_targets`] of the targets.
    pub targets: Vec<u8>,
}

/// The columns of a [`NamedPoseRow`], in its field order.
pub(super) const SELECT_NAMED_POSE: &str =
    "SELECT name, ordinal, revision, created_unix, constraints, pose, targets FROM named_poses";

impl NamedPoseRow {
    /// The row of `p` (counters past `i64::MAX` are clamped).
    pub(super) fn encode(p: &super::types::NamedPose) -> NamedPoseRow {
        let clamp = |x: u64| i64::try_from(x).unwrap_or(i64::MAX);
        NamedPoseRow {
            name: p.name.clone(),
            ordinal: clamp(p.ordinal),
            revision: clamp(p.revision),
            created_unix: clamp(p.created_unix),
            constraints: p.constraints.as_ref().map(|c| c.to_string()),
            pose: encode_points(&p.pose),
            targets: encode_targets(&p.targets),
        }
    }

    /// The named pose of a stored row of session `id` (checked as a
    /// checkpoint is: finite values, whole records).
    pub(super) fn decode(self, id: &str) -> Result<super::types::NamedPose, StoreError> {
        let what = format!("named pose `{}` of session `{id}`", self.name);
        let cp = decode_checkpoint(self.revision, 0, &self.pose, &self.targets, id).map_err(
            |e| match e {
                StoreError::Corrupt { reason, .. } => corrupt(&what, reason),
                e => e,
            },
        )?;
        let constraints = self
            .constraints
            .map(|c| serde_json::from_str(&c))
            .transpose()
            .map_err(|e| corrupt(&what, format!("constraints: {e}")))?;
        let nonneg = |x: i64, field: &str| {
            u64::try_from(x).map_err(|_| corrupt(&what, format!("negative {field}")))
        };
        Ok(super::types::NamedPose {
            ordinal: nonneg(self.ordinal, "ordinal")?,
            created_unix: nonneg(self.created_unix, "created_unix")?,
            name: self.name,
            revision: cp.revision,
            constraints,
            pose: cp.pose,
            targets: cp.targets,
        })
    }
}
