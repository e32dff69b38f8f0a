//! Prometheus metrics (`GET /metrics`, text exposition format).
//!
//! One [`prometheus::Registry`] per server instance (not a global recorder),
//! so several servers in one process (tests) keep separate counts.

use prometheus::{
    Encoder, Histogram, HistogramOpts, HistogramVec, IntCounter, IntGauge, Registry, TextEncoder,
};

use crate::error::ApiError;
use crate::session::Observer;

/// The server's metrics.
pub struct Metrics {
    registry: Registry,
    /// Live sessions.
    pub sessions: IntGauge,
    /// Sessions created since start.
    pub sessions_created: IntCounter,
    /// Connected WebSocket clients.
    pub ws_clients: IntGauge,
    /// Solves run.
    pub solves: IntCounter,
    /// Solves that ended converged.
    pub solves_converged: IntCounter,
    /// DEND iterations per solve.
    pub iterations: Histogram,
    /// Wall time of one solve (journal + factor lookup + iterations), seconds.
    pub solve_seconds: Histogram,
    /// Constraint set submitted → its factor available (built or cached), seconds.
    pub factor_ready_seconds: Histogram,
    /// A constraint set's coarse levels built beside its factor: build
    /// time, seconds.
    pub levels_ready_seconds: Histogram,
    /// Meshes stored.
    pub meshes: IntGauge,
    /// Factor cache: bytes held.
    pub factor_cache_bytes: IntGauge,
    /// Factor cache: factors held.
    pub factor_cache_entries: IntGauge,
    /// Factor cache: hits since start.
    pub factor_cache_hits: IntGauge,
    /// Factor cache: builds since start.
    pub factor_cache_builds: IntGauge,
    /// Sessions whose lease this instance holds (shared store), or live
    /// sessions (embedded store).
    pub sessions_owned: IntGauge,
    /// Sessions this instance took over from an instance whose lease expired.
    pub leases_taken_over: IntCounter,
    /// Sessions this instance handed over to an instance that asked for them.
    pub leases_handed_over: IntCounter,
    /// Wall time of each store call, seconds, by operation (`op`).
    pub store_seconds: HistogramVec,
    /// Solver scheduler: a solve's wait for a worker, seconds.
    pub schedule_delay_seconds: Histogram,
    /// Solver scheduler: solves waiting for a worker.
    pub solve_queue_depth: IntGauge,
    /// New sessions refused by admission control (503 `overloaded`).
    pub sessions_refused: IntCounter,
}

fn reg<T: prometheus::core::Collector + Clone + 'static>(r: &Registry, m: T) -> T {
    // Registration only fails on duplicate names, which are fixed here.
    if let Err(e) = r.register(Box::new(m.clone())) {
        tracing::error!(error = %e, "metric registration failed");
    }
    m
}

impl Metrics {
    /// A fresh registry with every metric registered.
    pub fn new() -> Result<Self, prometheus::Error> {
        let r = Registry::new_custom(Some("dend".into()), None)?;
        let latency = HistogramOpts::new("solve_seconds", "Wall time of one solve in seconds")
            .buckets(prometheus::exponential_buckets(0.0005, 2.0, 16)?);
        let iters =
            HistogramOpts::new("solve_iterations", "DEND iterations per solve").buckets(vec![
                1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0,
            ]);
        Ok(Metrics {
            sessions: reg(&r, IntGauge::new("sessions", "Live sessions")?),
            sessions_created: reg(
                &r,
                IntCounter::new("sessions_created_total", "Sessions created")?,
            ),
            ws_clients: reg(
                &r,
                IntGauge::new("ws_clients", "Connected WebSocket clients")?,
            ),
            solves: reg(&r, IntCounter::new("solves_total", "Solves run")?),
            solves_converged: reg(
                &r,
                IntCounter::new("solves_converged_total", "Solves that converged")?,
            ),
            iterations: reg(&r, Histogram::with_opts(iters)?),
            factor_ready_seconds: reg(
                &r,
                Histogram::with_opts(
                    HistogramOpts::new(
                        "factor_ready_seconds",
                        "Constraint set submitted -> factor available (built or cached), seconds",
                    )
                    .buckets(prometheus::exponential_buckets(0.001, 2.0, 16)?),
                )?,
            ),
            levels_ready_seconds: reg(
                &r,
                Histogram::with_opts(
                    HistogramOpts::new(
                        "levels_ready_seconds",
                        "A constraint set's coarse levels built beside its factor: build time, seconds",
                    )
                    .buckets(prometheus::exponential_buckets(0.001, 2.0, 16)?),
                )?,
            ),
            solve_seconds: reg(&r, Histogram::with_opts(latency)?),
            meshes: reg(&r, IntGauge::new("meshes", "Meshes stored")?),
            factor_cache_bytes: reg(
                &r,
                IntGauge::new("factor_cache_bytes", "Bytes held by cached factors")?,
            ),
            factor_cache_entries: reg(&r, IntGauge::new("factor_cache_entries", "Cached factors")?),
            factor_cache_hits: reg(
                &r,
                IntGauge::new("factor_cache_hits", "Factor cache hits since start")?,
            ),
            factor_cache_builds: reg(
                &r,
                IntGauge::new("factor_cache_builds", "Factors built since start")?,
            ),
            sessions_owned: reg(
                &r,
                IntGauge::new("sessions_owned", "Sessions leased by this instance")?,
            ),
            leases_taken_over: reg(
                &r,
                IntCounter::new(
                    "leases_taken_over_total",
                    "Session leases taken over from an instance whose lease expired",
                )?,
            ),
            leases_handed_over: reg(
                &r,
                IntCounter::new(
                    "leases_handed_over_total",
                    "Sessions handed over to the instance the load balancer routes them to",
                )?,
            ),
            store_seconds: reg(
                &r,
                HistogramVec::new(
                    HistogramOpts::new("store_seconds", "Wall time of one store call, seconds")
                        .buckets(prometheus::exponential_buckets(0.0001, 2.0, 18)?),
                    &["op"],
                )?,
            ),
            schedule_delay_seconds: reg(
                &r,
                Histogram::with_opts(
                    HistogramOpts::new(
                        "solve_schedule_delay_seconds",
                        "Solve submitted -> started on a solver worker, seconds",
                    )
                    .buckets(prometheus::exponential_buckets(0.0005, 2.0, 16)?),
                )?,
            ),
            solve_queue_depth: reg(
                &r,
                IntGauge::new("solve_queue_depth", "Solves waiting for a solver worker")?,
            ),
            sessions_refused: reg(
                &r,
                IntCounter::new(
                    "sessions_refused_total",
                    "New sessions refused by admission control (503 overloaded)",
                )?,
            ),
            registry: r,
        })
    }

    /// The text exposition of every metric.
    pub fn render(&self) -> Result<String, ApiError> {
        let mut buf = Vec::new();
        TextEncoder::new()
            .encode(&self.registry.gather(), &mut buf)
            .map_err(|e| ApiError::Internal(e.to_string()))?;
        String::from_utf8(buf).map_err(|e| ApiError::Internal(e.to_string()))
    }
}

impl Observer for Metrics {
    fn solved(&self, iterations: usize, seconds: f64, converged: bool) {
        self.solves.inc();
        if converged {
            self.solves_converged.inc();
        }
        self.iterations.observe(iterations as f64);
        self.solve_seconds.observe(seconds);
    }

    fn factor_ready(&self, seconds: f64) {
        self.factor_ready_seconds.observe(seconds);
    }

    fn levels_ready(&self, seconds: f64) {
        self.levels_ready_seconds.observe(seconds);
    }
}
