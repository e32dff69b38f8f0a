//! The server's one configuration struct: command-line flags, `DEND_*`
//! environment variables and (through serde) a JSON file, with a documented
//! default for every field.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use dend::deform::FactorPrecision;

/// Every limit and knob of `dend serve`. Flags win over environment
/// variables, which win over the defaults below.
#[derive(Debug, Clone, PartialEq, clap::Args, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Address to listen on (`HOST:PORT`; port 0 picks a free port).
    #[arg(long, env = "DEND_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: SocketAddr,
    /// Largest accepted request body in bytes (mesh uploads); larger → 413.
    #[arg(long, env = "DEND_MAX_UPLOAD_BYTES", default_value_t = 64 << 20)]
    pub max_upload_bytes: usize,
    /// Largest accepted mesh in vertices; larger → 413 `too_many_vertices`.
    #[arg(long, env = "DEND_MAX_VERTICES", default_value_t = 1_000_000)]
    pub max_vertices: usize,
    /// Most meshes kept at once; more → 503 `too_many_meshes`.
    #[arg(long, env = "DEND_MAX_MESHES", default_value_t = 1024)]
    pub max_meshes: usize,
    /// Most live sessions at once; more → 503 `too_many_sessions`.
    #[arg(long, env = "DEND_MAX_SESSIONS", default_value_t = 256)]
    pub max_sessions: usize,
    /// Memory budget of the shared factor cache in bytes (LRU eviction of
    /// factors only; an evicted factor is rebuilt on demand).
    #[arg(long, env = "DEND_FACTOR_CACHE_BYTES", default_value_t = 2 << 30)]
    pub factor_cache_bytes: usize,
    /// Precision the cached factors are stored in: `double`, or `single`
    /// (half the factor memory and solve traffic; steps are inexact to
    /// ~1e-4, which slows convergence on some meshes: docs/performance.md).
    #[arg(long, env = "DEND_FACTOR_PRECISION", default_value_t = FactorPrecision::Double)]
    pub factor_precision: FactorPrecision,
    /// A session with no request and no connected client for this many
    /// seconds is closed and deleted.
    #[arg(long, env = "DEND_IDLE_TIMEOUT_SECS", default_value_t = 3600)]
    pub idle_timeout_secs: u64,
    /// Time limit of one HTTP request in seconds (→ 408 `timeout`).
    #[arg(long, env = "DEND_REQUEST_TIMEOUT_SECS", default_value_t = 120)]
    pub request_timeout_secs: u64,
    /// Largest accepted WebSocket message in bytes (larger closes with 1009).
    #[arg(long, env = "DEND_WS_MAX_MESSAGE_BYTES", default_value_t = 64 << 10)]
    pub ws_max_message_bytes: usize,
    /// Most WebSocket messages a client may send per second (token bucket,
    /// burst of the same size); excess messages get an `error` event
    /// `rate_limited` and are not applied.
    #[arg(long, env = "DEND_WS_MAX_MESSAGES_PER_SEC", default_value_t = 500)]
    pub ws_max_messages_per_sec: u32,
    /// DEND iterations per pushed WebSocket frame while a drag settles.
    #[arg(long, env = "DEND_ITERS_PER_FRAME", default_value_t = 1)]
    pub iters_per_frame: usize,
    /// WebSocket drags are answered by coarse previews (frames of level 1:
    /// a level of about 4,000 vertices solved and prolongated to every
    /// vertex; meshes of 12,000+ vertices, the elastic formulation) while a
    /// fine iteration of the session takes longer than this many ms; the
    /// full mesh refines once the drags pause. 0: always; a negative
    /// value: never. Default 20 (a 50 frames/s budget: the 9,770-vertex
    /// camel's 5 ms iteration is never previewed, the 50k feline's 30 ms is).
    #[arg(
        long,
        env = "DEND_PREVIEW_ABOVE_MS",
        default_value_t = 20.0,
        allow_negative_numbers = true
    )]
    pub preview_above_ms: f64,
    /// Directory of the session store (SQLite file `dend.sqlite3`, created
    /// if missing): meshes, sessions, constraints, checkpoints and the drag
    /// journal survive restarts and crashes.
    #[arg(long, env = "DEND_DATA_DIR", default_value = "./dend-data")]
    pub data_dir: PathBuf,
    /// Keep everything in memory instead (nothing survives a restart).
    #[arg(long, env = "DEND_IN_MEMORY")]
    pub in_memory: bool,
    /// A shared store instead of the embedded one: a PostgreSQL URL
    /// (`postgres://user[:password]@host:port/db`). Several instances may
    /// share it; each live session is then leased by one instance
    /// (docs/deployment.md). Overrides `data_dir` and `in_memory`.
    #[arg(long, env = "DEND_STORE")]
    pub store: Option<String>,
    /// Most pooled connections to the shared store.
    #[arg(long, env = "DEND_STORE_CONNECTIONS", default_value_t = 16)]
    pub store_connections: u32,
    /// This instance's id in session leases and `session_owned_elsewhere`
    /// answers (default: `dend-` and 8 random hex digits, new every start).
    #[arg(long, env = "DEND_INSTANCE_ID")]
    pub instance_id: Option<String>,
    /// Lifetime of a session lease in milliseconds (shared store only): the
    /// owner renews it every third of this; when the owner dies, another
    /// instance takes the session over once it expires.
    #[arg(long, env = "DEND_LEASE_TTL_MS", default_value_t = 10_000)]
    pub lease_ttl_ms: u64,
    /// How long a drag that reaches a session while its factor is being
    /// built (after a constraint edit, or while the session is revived on
    /// this instance) waits for it, in milliseconds: it is applied once
    /// the session is ready (HTTP answers then; a WebSocket drag is
    /// acknowledged by the first frame after it); past this it is refused
    /// with 409 `not_ready`.
    #[arg(long, env = "DEND_BUILD_WAIT_MS", default_value_t = 30_000)]
    pub build_wait_ms: u64,
    /// Solver worker threads, shared round-robin by the sessions' solves
    /// (0: one per available core).
    #[arg(long, env = "DEND_SOLVER_THREADS", default_value_t = 0)]
    pub solver_threads: usize,
    /// Admission control: while this many sessions wait for a solver
    /// worker, a new session is refused with 503 `overloaded` and a
    /// `Retry-After` (existing sessions keep running). 0: 16 per solver
    /// thread.
    #[arg(long, env = "DEND_ADMISSION_WAITING_SESSIONS", default_value_t = 0)]
    pub admission_waiting_sessions: usize,
    /// On SIGTERM with a shared store (a rolling restart): how long the
    /// instance keeps serving while answering not ready, so that the load
    /// balancer takes it out of its ring, before it hands its sessions
    /// over, in milliseconds. At least the load balancer's health-check
    /// interval times its `fall` count.
    #[arg(long, env = "DEND_DRAIN_WAIT_MS", default_value_t = 2_500)]
    pub drain_wait_ms: u64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            max_upload_bytes: 64 << 20,
            max_vertices: 1_000_000,
            max_meshes: 1024,
            max_sessions: 256,
            factor_cache_bytes: 2 << 30,
            factor_precision: FactorPrecision::Double,
            idle_timeout_secs: 3600,
            request_timeout_secs: 120,
            ws_max_message_bytes: 64 << 10,
            ws_max_messages_per_sec: 500,
            iters_per_frame: 1,
            preview_above_ms: 20.0,
            data_dir: PathBuf::from("./dend-data"),
            in_memory: false,
            store: None,
            store_connections: 16,
            instance_id: None,
            lease_ttl_ms: 10_000,
            build_wait_ms: 30_000,
            solver_threads: 0,
            admission_waiting_sessions: 0,
            drain_wait_ms: 2_500,
        }
    }
}

impl Config {
    /// Reads a JSON config file (unknown keys are an error; missing keys
    /// take their defaults).
    pub fn from_json_file(path: &Path) -> anyhow::Result<Config> {
        let text = std::fs::read_to_string(path)?;
        Ok(serde_json::from_str(&text)?)
    }

    /// The idle timeout as a [`Duration`].
    pub fn idle_timeout(&self) -> Duration {
        Duration::from_secs(self.idle_timeout_secs)
    }

    /// The session lease lifetime as a [`Duration`].
    pub fn lease_ttl(&self) -> Duration {
        Duration::from_millis(self.lease_ttl_ms.max(100))
    }

    /// The drag queue's wait for a factor build as a [`Duration`].
    pub fn build_wait(&self) -> Duration {
        Duration::from_millis(self.build_wait_ms)
    }

    /// The admission limit (`admission_waiting_sessions`, or 16 per solver
    /// worker when 0) for `workers` solver workers.
    pub fn admission_limit(&self, workers: usize) -> usize {
        match self.admission_waiting_sessions {
            0 => 16 * workers.max(1),
            n => n,
        }
    }

    /// The drain's wait for the load balancer as a [`Duration`].
    pub fn drain_wait(&self) -> Duration {
        Duration::from_millis(self.drain_wait_ms)
    }

    /// The request timeout as a [`Duration`].
    pub fn request_timeout(&self) -> Duration {
        Duration::from_secs(self.request_timeout_secs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        config: Config,
    }

    #[test]
    fn clap_defaults_equal_serde_defaults() {
        let cli = Cli::try_parse_from(["x"]).unwrap();
        assert_eq!(cli.config, Config::default());
        let from_json: Config = serde_json::from_str("{}").unwrap();
        assert_eq!(from_json, Config::default());
    }

    #[test]
    fn unknown_file_keys_are_rejected() {
        assert!(serde_json::from_str::<Config>(r#"{"max_upload": 3}"#).is_err());
        let c: Config = serde_json::from_str(r#"{"max_sessions": 3}"#).unwrap();
        assert_eq!(c.max_sessions, 3);
    }

    #[test]
    fn flags_override_defaults() {
        let cli = Cli::try_parse_from(["x", "--addr", "0.0.0.0:9", "--max-vertices", "7"]).unwrap();
        assert_eq!(cli.config.addr.port(), 9);
        assert_eq!(cli.config.max_vertices, 7);
    }

    #[test]
    fn shared_store_flags() {
        let cli = Cli::try_parse_from([
            "x",
            "--store",
            "postgres://dend@127.0.0.1:5432/dend",
            "--instance-id",
            "dend1",
            "--lease-ttl-ms",
            "3000",
        ])
        .unwrap();
        assert_eq!(
            cli.config.store.as_deref(),
            Some("postgres://dend@127.0.0.1:5432/dend")
        );
        assert_eq!(cli.config.instance_id.as_deref(), Some("dend1"));
        assert_eq!(cli.config.lease_ttl(), Duration::from_secs(3));
        assert!(Cli::try_parse_from(["x", "--lease-ttl-ms", "soon"]).is_err());
    }

    #[test]
    fn factor_precision_from_flag_and_file() {
        let cli = Cli::try_parse_from(["x", "--factor-precision", "single"]).unwrap();
        assert_eq!(cli.config.factor_precision, FactorPrecision::Single);
        assert!(Cli::try_parse_from(["x", "--factor-precision", "half"]).is_err());
        let c: Config = serde_json::from_str(r#"{"factor_precision": "single"}"#).unwrap();
        assert_eq!(c.factor_precision, FactorPrecision::Single);
        assert!(serde_json::from_str::<Config>(r#"{"factor_precision": "f16"}"#).is_err());
    }
}
