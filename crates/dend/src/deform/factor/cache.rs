//! The factor cache: every built [`Factor`] of a process, keyed by
//! [`FactorKey`], LRU under a byte budget, with single-flight builds.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use parking_lot::Mutex;

use super::options::SolveOptions;
use super::stage::BuildStage;
use super::{Factor, FactorKey};
use crate::deform::constraints::Constraints;
use crate::deform::error::DeformError;
use crate::deform::params::Params;
use crate::deform::rest::Rest;

/// An LRU cache of factors under a byte budget, shared by every session of a
/// process. Evicts factors only (they are rebuilt on demand); counts builds
/// and hits so that "changing only targets never refactors" is testable.
pub struct FactorCache {
    budget: usize,
    /// How every factor of this cache is built (precision, ordering, CG
    /// fallback budget); not part of the key, one set per cache.
    options: SolveOptions,
    inner: Mutex<CacheInner>,
    builds: AtomicU64,
    hits: AtomicU64,
}

struct CacheInner {
    map: HashMap<FactorKey, (Arc<Factor>, u64)>,
    /// One gate per key being built: concurrent requests for the same
    /// constraint set (sessions opened together on one mesh) wait for the
    /// first build instead of each factoring `M` again.
    building: HashMap<FactorKey, Arc<Mutex<()>>>,
    tick: u64,
    bytes: usize,
}

impl FactorCache {
    /// An empty cache holding at most `budget_bytes` of factors (the most
    /// recent one is always kept, even if it alone exceeds the budget).
    pub fn new(budget_bytes: usize) -> Self {
        Self::with_options(budget_bytes, SolveOptions::default())
    }

    /// [`FactorCache::new`] whose factors are built with `options`.
    pub fn with_options(budget_bytes: usize, options: SolveOptions) -> Self {
        FactorCache {
            budget: budget_bytes,
            options,
            inner: Mutex::new(CacheInner {
                map: HashMap::new(),
                building: HashMap::new(),
                tick: 0,
                bytes: 0,
            }),
            builds: AtomicU64::new(0),
            hits: AtomicU64::new(0),
        }
    }

    /// The cached factor for this key, or a new one (built outside the lock).
    pub fn get_or_build(
        &self,
        rest: &Rest,
        params: &Params,
        constraints: &Constraints,
    ) -> Result<Arc<Factor>, DeformError> {
        self.get_or_build_reporting(rest, params, constraints, &|_| {})
    }

    /// [`FactorCache::get_or_build`] calling `progress` as each stage of a
    /// build starts ([`Factor::build_reporting`]); a cache hit reports
    /// nothing.
    pub fn get_or_build_reporting(
        &self,
        rest: &Rest,
        params: &Params,
        constraints: &Constraints,
        progress: &dyn Fn(BuildStage),
    ) -> Result<Arc<Factor>, DeformError> {
        let key = FactorKey::new(rest, params, constraints);
        let lookup = |inner: &mut CacheInner| {
            inner.tick += 1;
            let tick = inner.tick;
            inner.map.get_mut(&key).map(|(f, used)| {
                *used = tick;
                f.clone()
            })
        };
        let gate = {
            let mut inner = self.inner.lock();
            if let Some(f) = lookup(&mut inner) {
                self.hits.fetch_add(1, Ordering::Relaxed);
                return Ok(f);
            }
            inner.building.entry(key.clone()).or_default().clone()
        };
        // Single flight: whoever holds the gate builds; the others find the
        // factor in the map once it is released (or build themselves if
        // that build failed).
        let _building = gate.lock();
        if let Some(f) = lookup(&mut self.inner.lock()) {
            self.hits.fetch_add(1, Ordering::Relaxed);
            return Ok(f);
        }
        let t0 = std::time::Instant::now();
        let built = Factor::build_reporting(rest, params, constraints, &self.options, progress);
        if let Ok(f) = &built {
            let t = f.timings();
            let ms = |d: std::time::Duration| (d.as_secs_f64() * 1e4).round() / 10.0;
            tracing::info!(
                unknowns = f.num_unknowns(),
                total_ms = ms(t0.elapsed()),
                assembly_ms = ms(t.assembly),
                symbolic_ms = ms(t.symbolic),
                numeric_ms = ms(t.numeric),
                "factor built"
            );
        }
        let mut inner = self.inner.lock();
        // Waiters hold their own copy of the gate; later requests find the
        // factor (inserted below under this same lock) or build anew.
        inner.building.remove(&key);
        let factor = Arc::new(built?);
        self.builds.fetch_add(1, Ordering::Relaxed);
        inner.tick += 1;
        let tick = inner.tick;
        let bytes = factor.memory_bytes();
        if let Some((old, _)) = inner.map.insert(key.clone(), (factor.clone(), tick)) {
            inner.bytes -= old.memory_bytes();
        }
        inner.bytes += bytes;
        while inner.bytes > self.budget && inner.map.len() > 1 {
            let victim = inner
                .map
                .iter()
                .filter(|(k, _)| **k != key)
                .min_by_key(|(_, (_, used))| *used)
                .map(|(k, _)| k.clone());
            match victim {
                Some(k) => {
                    if let Some((f, _)) = inner.map.remove(&k) {
                        inner.bytes -= f.memory_bytes();
                    }
                }
                None => break,
            }
        }
        Ok(factor)
    }

    /// Drops every factor built on `rest_id` (e.g. when its mesh is deleted).
    pub fn evict_rest(&self, rest_id: u64) {
        let mut inner = self.inner.lock();
        let keys: Vec<FactorKey> = inner
            .map
            .keys()
            .filter(|k| k.rest_id == rest_id)
            .cloned()
            .collect();
        for k in keys {
            if let Some((f, _)) = inner.map.remove(&k) {
                inner.bytes -= f.memory_bytes();
            }
        }
    }

    /// Factor builds so far.
    pub fn builds(&self) -> u64 {
        self.builds.load(Ordering::Relaxed)
    }

    /// Cache hits so far.
    pub fn hits(&self) -> u64 {
        self.hits.load(Ordering::Relaxed)
    }

    /// Bytes currently held.
    pub fn bytes(&self) -> usize {
        self.inner.lock().bytes
    }

    /// Factors currently held.
    pub fn len(&self) -> usize {
        self.inner.lock().map.len()
    }

    /// Whether the cache is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The byte budget.
    pub fn budget(&self) -> usize {
        self.budget
    }
}
