//! Owner liveness through PostgreSQL: how a surviving instance learns at
//! once that a lease's owner died, instead of waiting for the lease to
//! expire (docs/deployment.md, "Failover in seconds").
//!
//! Each instance keeps one connection of its own open for its whole life
//! (not pooled), named `dend-live:<instance>` (`application_name`). When
//! the process dies, however it dies (crash, SIGKILL, out of memory), its
//! kernel closes that socket and PostgreSQL ends the backend within
//! milliseconds; a live but CPU-starved or frozen process keeps its socket
//! open, so it keeps its leases until they expire. [`holder_liveness`] is
//! checked in the takeover's transaction: a live lease whose owner has no
//! liveness connection is taken over as if it had expired, only when
//! - the asking instance sees its *own* liveness connection (a pooler in
//!   front of PostgreSQL that hides backends turns the check off by itself),
//! - and the database has been up for longer than [`RECONNECT_GRACE`] (after
//!   a PostgreSQL restart every instance reconnects within it).
//!
//! A false "gone" (the owner alive but cut from PostgreSQL for longer than
//! the grace) is safe: the takeover raises the fencing revision, and the
//! old owner's writes are refused; it loses the session at its next renewal.
//!
//! The liveness connection also asks the server for TCP keep-alives every
//! second (`tcp_keepalives_*`, `tcp_user_timeout`), so that a host that
//! vanishes without closing its sockets (power loss, a partition) is noticed
//! in about [`HOST_LOSS`] rather than the kernel's two hours.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use postgres::NoTls;

use super::conn::pg_err;
use crate::store::types::StoreError;

/// How long after a PostgreSQL start the liveness check stays off: the
/// instances' liveness connections are back well within it.
pub const RECONNECT_GRACE: Duration = Duration::from_secs(3);

/// About how long PostgreSQL takes to end the liveness connection of a
/// host that vanished without closing it (keep-alive idle 2 s, then 3
/// probes 1 s apart).
pub const HOST_LOSS: Duration = Duration::from_secs(5);

/// How often the liveness thread checks its connection (and reconnects).
const CHECK_EVERY: Duration = Duration::from_millis(500);

/// The `application_name` of `instance`'s liveness connection (cut to
/// PostgreSQL's 63 bytes, as the server stores it).
pub fn liveness_name(instance: &str) -> String {
    let mut name = format!("dend-live:{instance}");
    let mut cut = name.len().min(63);
    while !name.is_char_boundary(cut) {
        cut -= 1;
    }
    name.truncate(cut);
    name
}

/// The liveness connection's thread; stops when dropped.
pub(super) struct Liveness {
    stop: Arc<AtomicBool>,
}

impl Drop for Liveness {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Opens `instance`'s liveness connection with `config` (the pool's
/// settings) and keeps it open on a thread of its own, reconnecting when it
/// breaks; returns once the first connection is up (or failed).
pub(super) fn start(config: &postgres::Config, instance: &str) -> Result<Liveness, StoreError> {
    let mut config = config.clone();
    let _ = config.application_name(&liveness_name(instance));
    let options = format!(
        "{} -c tcp_keepalives_idle=2 -c tcp_keepalives_interval=1 -c tcp_keepalives_count=3 \
         -c tcp_user_timeout={}",
        config.get_options().unwrap_or_default(),
        HOST_LOSS.as_millis()
    );
    let _ = config.options(options.trim());
    let stop = Arc::new(AtomicBool::new(false));
    let (first_tx, first_rx) = std::sync::mpsc::channel();
    let flag = stop.clone();
    let _ = std::thread::Builder::new()
        .name("dend-liveness".into())
        .spawn(move || {
            let mut first = Some(first_tx);
            while !flag.load(Ordering::Relaxed) {
                match config.connect(NoTls) {
                    Ok(mut client) => {
                        if let Some(tx) = first.take() {
                            let _ = tx.send(Ok(()));
                        }
                        while !flag.load(Ordering::Relaxed) {
                            std::thread::sleep(CHECK_EVERY);
                            if client.simple_query("SELECT 1").is_err() {
                                tracing::warn!(
                                    "the liveness connection to PostgreSQL broke: reconnecting"
                                );
                                break;
                            }
                        }
                    }
                    Err(e) => {
                        if let Some(tx) = first.take() {
                            let _ = tx.send(Err(pg_err(e)));
                        }
                        std::thread::sleep(CHECK_EVERY / 2);
                    }
                }
            }
        })
        .map_err(|e| StoreError::Backend(format!("liveness thread: {e}")))?;
    match first_rx.recv_timeout(Duration::from_secs(10)) {
        Ok(Ok(())) => {}
        // it keeps trying: until it connects, this instance's own check
        // fails and others' leases are only taken once expired
        Ok(Err(e)) => tracing::warn!(error = %e, "no liveness connection yet"),
        Err(_) => tracing::warn!("no liveness connection yet"),
    }
    Ok(Liveness { stop })
}

/// What the liveness connections say about a lease's holder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Holder {
    /// Its liveness connection is there, or the check is off (the asking
    /// instance does not see its own: a pooler hides backends).
    Present,
    /// Its liveness connection is missing, but the database started less
    /// than [`RECONNECT_GRACE`] ago: it may still be reconnecting. This
    /// is known in `left_ms`, when the grace ends.
    Unknown {
        /// Milliseconds until the grace ends.
        left_ms: u64,
    },
    /// Its liveness connection is missing past the grace: it is gone.
    Gone,
}

/// Whether `holder`, which holds a live lease that `asking` wants, is gone:
/// no liveness connection, while `asking`'s own is seen and the database
/// has been up for longer than [`RECONNECT_GRACE`] (inside the grace the
/// answer is [`Holder::Unknown`] until it ends). Inside the takeover's
/// transaction.
pub(super) fn holder_liveness(
    tx: &mut postgres::Transaction<'_>,
    asking: &str,
    holder: &str,
) -> Result<Holder, StoreError> {
    let grace_ms = RECONNECT_GRACE.as_secs_f64() * 1000.0;
    let row = tx
        .query_one(
            "SELECT EXISTS (SELECT 1 FROM pg_stat_activity WHERE application_name = $1),
                    EXISTS (SELECT 1 FROM pg_stat_activity WHERE application_name = $2),
                    GREATEST(0, CEIL(EXTRACT(EPOCH FROM (pg_postmaster_start_time()
                        + $3::FLOAT8 * INTERVAL '1 millisecond' - now())) * 1000))::BIGINT",
            &[&liveness_name(asking), &liveness_name(holder), &grace_ms],
        )
        .map_err(pg_err)?;
    let (asking_seen, holder_seen, grace_left): (bool, bool, i64) =
        (row.get(0), row.get(1), row.get(2));
    Ok(classify(asking_seen, holder_seen, grace_left))
}

/// [`holder_liveness`]'s rule. Inside the grace the answer is
/// [`Holder::Unknown`] whether or not the asking instance's own liveness
/// connection is back yet: its thread reconnects within the grace too, so
/// the answer is known when the grace ends (a refusal's retry hint), not
/// when the lease expires. Past the grace, an asking instance that does
/// not see its own connection has the check off (a pooler hides backends).
fn classify(asking_seen: bool, holder_seen: bool, grace_left: i64) -> Holder {
    if holder_seen {
        Holder::Present
    } else if grace_left > 0 {
        Holder::Unknown {
            left_ms: grace_left.unsigned_abs(),
        }
    } else if !asking_seen {
        Holder::Present
    } else {
        Holder::Gone
    }
}

#[cfg(test)]
mod tests {
    use super::{classify, liveness_name, Holder};

    #[test]
    fn inside_the_grace_the_holder_is_unknown_even_before_the_own_connection_is_back() {
        // just after a PostgreSQL restart neither connection is back yet:
        // the retry hint must be the grace's end, not the lease's
        assert_eq!(
            classify(false, false, 2500),
            Holder::Unknown { left_ms: 2500 }
        );
        assert_eq!(classify(true, false, 10), Holder::Unknown { left_ms: 10 });
        // a holder seen is present, inside the grace or not
        assert_eq!(classify(false, true, 2500), Holder::Present);
        assert_eq!(classify(true, true, 0), Holder::Present);
        // past the grace: gone only when the asking instance sees itself
        assert_eq!(classify(true, false, 0), Holder::Gone);
        assert_eq!(classify(false, false, 0), Holder::Present);
    }

    #[test]
    fn liveness_names_fit_postgres() {
        assert_eq!(liveness_name("dend1"), "dend-live:dend1");
        let long = "é".repeat(40);
        let n = liveness_name(&long);
        assert!(n.len() <= 63 && n.starts_with("dend-live:é"));
    }
}
