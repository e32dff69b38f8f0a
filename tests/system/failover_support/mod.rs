//! The processes of the multi-instance failover test: a throw-away
//! PostgreSQL (`scripts/pg-temp.sh`), `dend serve` instances sharing it, and
//! HAProxy in front hashing the session id (the same rules as
//! `docker/haproxy.cfg`). Everything listens on loopback ports and lives in
//! one temporary directory; dropping a [`Cluster`] stops every process.
#![allow(dead_code)]

pub mod client;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Why the cluster cannot run here (missing binaries), or a start failure.
pub type Result<T> = std::result::Result<T, String>;

/// A free loopback port (bound, then released).
pub fn free_port() -> Result<u16> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| format!("no free port: {e}"))
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn pg_script(args: &[&str]) -> Result<String> {
    let out = Command::new("bash")
        .arg(repo().join("scripts/pg-temp.sh"))
        .args(args)
        .output()
        .map_err(|e| format!("running pg-temp.sh: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "pg-temp.sh {args:?} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

/// The binaries the cluster needs, or why they are missing.
pub fn prerequisites() -> Result<PathBuf> {
    pg_script(&["bindir"]).map_err(|_| {
        "PostgreSQL server binaries not found (apt-get install postgresql)".to_owned()
    })?;
    which("haproxy").ok_or_else(|| "haproxy not found (apt-get install haproxy)".to_owned())
}

/// PostgreSQL's server binaries, or why they are missing (for the tests
/// that run instances on PostgreSQL without HAProxy).
pub fn postgres_prerequisite() -> Result<()> {
    pg_script(&["bindir"])
        .map(|_| ())
        .map_err(|_| "PostgreSQL server binaries not found (apt-get install postgresql)".to_owned())
}

fn which(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/sbin")])
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// A PostgreSQL server in its own data directory.
pub struct Postgres {
    dir: PathBuf,
    port: u16,
    /// `postgres://dend@127.0.0.1:PORT/postgres`.
    pub url: String,
}

impl Postgres {
    /// initdb (first time) and start, waiting until it accepts connections.
    pub fn start(dir: &Path, port: u16) -> Result<Postgres> {
        let d = dir.display().to_string();
        let url = pg_script(&["start", &d, &port.to_string()])?;
        Ok(Postgres {
            dir: dir.to_owned(),
            port,
            url,
        })
    }

    /// The first column of the first row of `sql` (psql, unaligned).
    pub fn query(&self, sql: &str) -> Result<String> {
        let bin = pg_script(&["bindir"])?;
        let out = Command::new(Path::new(&bin).join("psql"))
            .args([self.url.as_str(), "-Atc", sql])
            .output()
            .map_err(|e| format!("psql: {e}"))?;
        if !out.status.success() {
            return Err(String::from_utf8_lossy(&out.stderr).into_owned());
        }
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_owned())
    }

    /// Fast shutdown (open connections are cut).
    pub fn stop(&self) -> Result<()> {
        pg_script(&["stop", &self.dir.display().to_string()]).map(|_| ())
    }

    /// Starts it again on the same port and data.
    pub fn restart(&self) -> Result<()> {
        pg_script(&[
            "start",
            &self.dir.display().to_string(),
            &self.port.to_string(),
        ])
        .map(|_| ())
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// One `dend serve` instance.
pub struct Instance {
    /// Its instance id (`dend1`…).
    pub id: String,
    /// `http://127.0.0.1:PORT`.
    pub base: String,
    /// Its port.
    pub port: u16,
    child: Option<Child>,
}

impl Instance {
    /// Starts `dend serve` on the shared store; waits until ready.
    pub fn start(dir: &Path, id: &str, store: &str, lease_ttl_ms: u64) -> Result<Instance> {
        Self::start_on(dir, id, store, lease_ttl_ms, free_port()?)
    }

    /// [`start`](Self::start) on a given port (an instance coming back).
    pub fn start_on(
        dir: &Path,
        id: &str,
        store: &str,
        lease_ttl_ms: u64,
        port: u16,
    ) -> Result<Instance> {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(dir.join(format!("{id}.log")))
            .map_err(|e| format!("log file: {e}"))?;
        let err = log.try_clone().map_err(|e| e.to_string())?;
        let child = Command::new(env!("CARGO_BIN_EXE_dend"))
            .args(["serve", "--addr", &format!("127.0.0.1:{port}")])
            .args(["--store", store, "--instance-id", id])
            .args(["--lease-ttl-ms", &lease_ttl_ms.to_string()])
            .args(["--store-connections", "8"])
            .env("RUST_LOG", "info")
            .stdout(Stdio::from(log))
            .stderr(Stdio::from(err))
            .spawn()
            .map_err(|e| format!("starting dend serve: {e}"))?;
        let inst = Instance {
            id: id.to_owned(),
            base: format!("http://127.0.0.1:{port}"),
            port,
            child: Some(child),
        };
        wait_http(
            &format!("{}/healthz/ready", inst.base),
            Duration::from_secs(60),
        )?;
        Ok(inst)
    }

    /// SIGKILL: no shutdown, no lease release.
    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill(); // SIGKILL on Unix
            let _ = c.wait();
        }
    }

    /// Sends a signal (`STOP`, `CONT`) with kill(1).
    pub fn signal(&self, sig: &str) -> Result<()> {
        let pid = self.child.as_ref().ok_or("not running")?.id();
        let st = Command::new("kill")
            .args(["-s", sig, &pid.to_string()])
            .status()
            .map_err(|e| format!("kill -s {sig}: {e}"))?;
        st.success()
            .then_some(())
            .ok_or_else(|| format!("kill -s {sig} {pid} failed"))
    }

    /// Whether the process still runs.
    pub fn alive(&self) -> bool {
        self.child.is_some()
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Polls `url` until it answers 200.
pub fn wait_http(url: &str, timeout: Duration) -> Result<()> {
    let end = Instant::now() + timeout;
    loop {
        if http_status(url) == Some(200) {
            return Ok(());
        }
        if Instant::now() > end {
            return Err(format!("{url} not ready within {timeout:?}"));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The status of a plain `GET url` (HTTP/1.0 over a raw socket; no client
/// runtime needed), or None when nothing answers.
pub fn http_status(url: &str) -> Option<u16> {
    use std::io::{Read, Write};
    let rest = url.strip_prefix("http://")?;
    let (host, path) = rest.split_once('/').unwrap_or((rest, ""));
    let mut s = std::net::TcpStream::connect(host).ok()?;
    let _ = s.set_read_timeout(Some(Duration::from_secs(5)));
    write!(s, "GET /{path} HTTP/1.0\r\nHost: {host}\r\n\r\n").ok()?;
    let mut buf = [0u8; 32];
    let n = s.read(&mut buf).ok()?;
    let head = std::str::from_utf8(&buf[..n]).ok()?;
    head.split_whitespace().nth(1)?.parse().ok()
}

/// HAProxy in front of the instances.
pub struct Haproxy {
    /// `http://127.0.0.1:PORT`.
    pub base: String,
    child: Child,
}

/// The HAProxy configuration: the rules of `docker/haproxy.cfg` with
/// loopback addresses.
pub fn haproxy_config(port: u16, servers: &[(String, u16)]) -> String {
    let mut cfg = format!(
        "global
    maxconn 4096
defaults
    mode http
    timeout connect 1s
    timeout client 60s
    timeout server 60s
    timeout tunnel 1h
    timeout client-fin 5s
    retries 2
    option redispatch 1
frontend dend
    bind 127.0.0.1:{port}
    default_backend dend
backend dend
    balance uri path-only depth 3
    hash-type consistent
    option httpchk GET /healthz/ready
    http-check expect status 200
    default-server inter 300ms fastinter 200ms downinter 500ms fall 2 rise 2
"
    );
    for (id, p) in servers {
        cfg.push_str(&format!("    server {id} 127.0.0.1:{p} check\n"));
    }
    cfg
}

impl Haproxy {
    /// Starts HAProxy (foreground, `-db`) with [`haproxy_config`].
    pub fn start(dir: &Path, bin: &Path, servers: &[(String, u16)]) -> Result<Haproxy> {
        let port = free_port()?;
        let cfg = dir.join("haproxy.cfg");
        std::fs::write(&cfg, haproxy_config(port, servers)).map_err(|e| e.to_string())?;
        let log = std::fs::File::create(dir.join("haproxy.log")).map_err(|e| e.to_string())?;
        let child = Command::new(bin)
            .arg("-db")
            .arg("-f")
            .arg(&cfg)
            .stdout(Stdio::from(log.try_clone().map_err(|e| e.to_string())?))
            .stderr(Stdio::from(log))
            .spawn()
            .map_err(|e| format!("starting haproxy: {e}"))?;
        let h = Haproxy {
            base: format!("http://127.0.0.1:{port}"),
            child,
        };
        wait_http(&format!("{}/healthz", h.base), Duration::from_secs(20))?;
        Ok(h)
    }
}

impl Drop for Haproxy {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
