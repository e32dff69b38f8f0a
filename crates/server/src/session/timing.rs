//! How long a gesture lasts for a session, and the wait its loops use.

/// How long after a WebSocket drag the session treats drags as one
/// gesture: coarse previews answer them on large meshes, and the solves
/// that answer a drag hold the coarse corrections
/// (`Deformer::hold_corrections`). A refinement's corrections run (a drag
/// that arrives stops them, `Actor::interrupt`): camel closed loop, settle
/// 37–39 → 21 iterations, 560–604 → 501–510 ms. 150 ms: drags 125 ms apart (a
/// person dragging slowly, 8 mouse moves a second) stay on coarse previews
/// on the feline (drag→frame p50 26.8 ms, p99 59 ms; at 100 ms the full
/// mesh iterated between them: 48.1 and 104 ms), for a settle that starts
/// 50 ms later (docs/performance.md).
pub const CORRECTION_QUIET: std::time::Duration = std::time::Duration::from_millis(150);

/// The longest a reconnecting client's first frame, or a pose read,
/// waits for the drags the session holds and no frame shows yet
/// (`SessionHandle::drags_shown`). The session answers as soon as they are
/// shown or refused, or when it closes: a solve step takes milliseconds,
/// drags queued for a factor build wait for it (refused after
/// `build_wait_ms`, 30 s by default). This bound is a safety net past
/// that; past it the current frame goes out, and a drag it does not show
/// yet may be sent twice.
pub const DRAGS_SHOWN_WAIT: std::time::Duration = std::time::Duration::from_secs(60);

/// Sleeps until `at`; never when `None` (for a `select!` branch that is
/// disabled then: the session's wake-up, a connection's rate interval).
pub(crate) async fn sleep_until_or_never(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}
