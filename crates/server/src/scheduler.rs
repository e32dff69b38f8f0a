//! The solver scheduler: every session's solver work on a fixed set of
//! worker threads, shared fairly between sessions (docs/deployment.md, "Fair scheduling").
//!
//! A session [`submit`](Scheduler::submit)s its solves one at a time (the
//! journal append and one `Deformer::step` of its iteration budget). Jobs
//! wait in one queue per session; the sessions with work wait in a ring.
//! Each free worker takes the session at the front of the ring, runs *one*
//! of its jobs (a turn's bounded batch) and puts the session back at the end
//! of the ring when it has more. With `S` sessions waiting and `W` workers,
//! a job therefore waits for at most about `S / W` other jobs, however
//! much work any one session submits. Tokio's blocking pool, which ran the
//! solves before, starts a thread per job and leaves the interleaving to
//! the operating system, without a bound on how long one session's solve
//! waits behind the others'.
//!
//! There are as many workers as cores (by default), not a thread per
//! solve: the HTTP and WebSocket tasks, lease renewals and the store's
//! liveness connection are not outnumbered by dozens of runnable solver
//! threads when the solvers saturate the cores.
//!
//! Threads of one solve: a job that runs alone (no other session's job
//! running or waiting) spreads its parallel loops over every core (rayon's
//! shared pool); a job that runs beside others stays on its worker's own
//! one-thread pool. With every core busy, splitting a solve's loops only
//! adds the cost of splitting them (the two-thread sweeps' accumulators,
//! waking threads, waiting for the slower half), and the sessions' solves
//! already use the cores side by side. Eight camel_9770 sessions on two
//! cores (`dend loadtest --sessions 8 --drags 100`, same run, 2 runs each):
//! settle 1.34 → 1.03–1.09 s, drag→frame p50 39–41 → 29–32 ms, p99 67–71 →
//! 44–45 ms, the same iterations (docs/performance.md).
//!
//! Refinements (a session's steps while nobody waits for its answer: a
//! settle, or the refinement between drags) share the turns round the
//! ring as any job does, but a refinement's turn goes to the session whose
//! run of refinements began earliest: when the session at the front has a
//! refinement to run and another session's run began earlier, that one
//! runs, and the front goes to the back of the ring. Every pick still
//! takes the front off the ring, so a drag's answer waits for at most one
//! job per session ahead of it, as above; and sessions that settle at once
//! finish one or two at a time (as many as there are workers), the
//! earliest first, instead of all together at the end: the same work, the
//! others sooner (eight camel_9770 sessions on two cores, docs/performance.md).
//! A refinement still waiting when a drag of its session comes in stops
//! after an iteration to answer it, so it becomes that answer
//! ([`answer_now`](Scheduler::answer_now)) and no longer waits behind
//! other sessions' settles.
//!
//! Admission: [`waiting`](Scheduler::waiting) is the number of sessions
//! whose solve waits for a worker; the server refuses new sessions while it
//! is at `Config::admission_waiting_sessions` (503 `overloaded`, with
//! `Retry-After`).

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::time::Instant;

use parking_lot::{Condvar, Mutex};
use prometheus::{Histogram, IntGauge};

/// What the scheduler reports (the server's metrics).
#[derive(Clone)]
pub struct SchedulerMetrics {
    /// Seconds from a job's submission to its start.
    pub delay: Histogram,
    /// Jobs waiting for a worker.
    pub depth: IntGauge,
}

type Job = Box<dyn FnOnce() + Send + 'static>;

/// A waiting job: the job, its submission time, and for a refinement when
/// the session's run of refinements began ([`Scheduler::submit_refinement`]).
type Queued = (Job, Instant, Option<Instant>);

struct State {
    /// Each session's waiting jobs, oldest first.
    queues: HashMap<String, VecDeque<Queued>>,
    /// Sessions with waiting jobs, in the order they get their next turn.
    ring: VecDeque<String>,
    /// Jobs waiting.
    depth: usize,
    /// The session of each running job. A session's next solve is often
    /// taken while its previous job returns (the job's result reaches the
    /// session, which submits the next, before the worker is free): that
    /// job is no other session's, and the next one still runs alone.
    running: Vec<String>,
    /// Set when the scheduler is dropped: workers finish what is queued
    /// and end.
    stop: bool,
}

struct Shared {
    state: Mutex<State>,
    work: Condvar,
    metrics: Option<SchedulerMetrics>,
}

/// Runs the sessions' solves on `workers` threads, round-robin across
/// sessions (see the module docs). Dropping it ends the workers once the
/// queued jobs ran.
pub struct Scheduler {
    shared: Arc<Shared>,
    workers: usize,
}

impl std::fmt::Debug for Scheduler {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scheduler")
            .field("workers", &self.workers)
            .field("waiting", &self.waiting())
            .finish()
    }
}

impl Scheduler {
    /// A scheduler with `workers` threads (0: one per available core).
    pub fn new(workers: usize, metrics: Option<SchedulerMetrics>) -> Scheduler {
        let workers = if workers == 0 {
            std::thread::available_parallelism().map_or(2, |n| n.get())
        } else {
            workers
        };
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                queues: HashMap::new(),
                ring: VecDeque::new(),
                depth: 0,
                running: Vec::new(),
                stop: false,
            }),
            work: Condvar::new(),
            metrics,
        });
        for k in 0..workers {
            let shared = shared.clone();
            let spawned = std::thread::Builder::new()
                .name(format!("dend-solver-{k}"))
                .spawn(move || worker(&shared));
            if let Err(e) = spawned {
                tracing::error!(error = %e, "starting a solver thread failed");
            }
        }
        Scheduler { shared, workers }
    }

    /// Queues `job` as session `session`'s; it runs on a worker at the
    /// session's next turn, after the jobs it submitted before.
    pub fn submit(&self, session: &str, job: impl FnOnce() + Send + 'static) {
        self.queue(session, Box::new(job), None);
    }

    /// [`Scheduler::submit`] for a refinement, one of a run of them that
    /// began at `since`: among refinements, the earliest run goes first
    /// (module docs).
    pub fn submit_refinement(
        &self,
        session: &str,
        since: Instant,
        job: impl FnOnce() + Send + 'static,
    ) {
        self.queue(session, Box::new(job), Some(since));
    }

    fn queue(&self, session: &str, job: Job, since: Option<Instant>) {
        let mut st = self.shared.state.lock();
        let queue = st.queues.entry(session.to_owned()).or_default();
        let was_idle = queue.is_empty();
        queue.push_back((job, Instant::now(), since));
        if was_idle {
            st.ring.push_back(session.to_owned());
        }
        st.depth += 1;
        if let Some(m) = &self.shared.metrics {
            m.depth.set(st.depth as i64);
        }
        drop(st);
        let _ = self.shared.work.notify_one();
    }

    /// Makes `session`'s waiting refinements jobs that answer a drag: a
    /// drag came in behind one of them, which will stop after an
    /// iteration to answer it (module docs).
    pub fn answer_now(&self, session: &str) {
        let mut st = self.shared.state.lock();
        if let Some(queue) = st.queues.get_mut(session) {
            for job in queue.iter_mut() {
                job.2 = None;
            }
        }
    }

    /// Sessions whose next job waits for a worker (the admission load).
    pub fn waiting(&self) -> usize {
        self.shared.state.lock().ring.len()
    }

    /// Jobs waiting for a worker.
    pub fn depth(&self) -> usize {
        self.shared.state.lock().depth
    }

    /// The number of worker threads.
    pub fn workers(&self) -> usize {
        self.workers
    }
}

impl Drop for Scheduler {
    fn drop(&mut self) {
        self.shared.state.lock().stop = true;
        let _ = self.shared.work.notify_all();
    }
}

fn worker(shared: &Shared) {
    // this worker's pool for the jobs that run beside others (module docs)
    let own = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "dend-solver-own".into())
        .build()
        .map_err(|e| tracing::warn!(error = %e, "a solver's own thread pool failed to start"))
        .ok();
    loop {
        let ((job, at, _), session, beside_others) = {
            let mut st = shared.state.lock();
            loop {
                if let Some(front) = st.ring.pop_front() {
                    let session = next_session(&mut st, front);
                    let Some(queue) = st.queues.get_mut(&session) else {
                        continue;
                    };
                    let Some(job) = queue.pop_front() else {
                        let _ = st.queues.remove(&session);
                        continue;
                    };
                    if queue.is_empty() {
                        let _ = st.queues.remove(&session);
                    } else {
                        // its next job waits for its next turn
                        st.ring.push_back(session.clone());
                    }
                    st.depth -= 1;
                    if let Some(m) = &shared.metrics {
                        m.depth.set(st.depth as i64);
                    }
                    let beside_others = st.running.iter().any(|s| *s != session)
                        || st.ring.iter().any(|s| *s != session);
                    st.running.push(session.clone());
                    break (job, session, beside_others);
                }
                if st.stop {
                    return;
                }
                shared.work.wait(&mut st);
            }
        };
        if let Some(m) = &shared.metrics {
            m.delay.observe(at.elapsed().as_secs_f64());
        }
        // a panicking solve loses its session's reply (as a panicking
        // blocking task did), not the worker
        let job = std::panic::AssertUnwindSafe(job);
        match &own {
            Some(pool) if beside_others => {
                let _ = pool.install(|| std::panic::catch_unwind(job));
            }
            _ => {
                let _ = std::panic::catch_unwind(job);
            }
        }
        let mut st = shared.state.lock();
        if let Some(k) = st.running.iter().position(|s| *s == session) {
            st.running.swap_remove(k);
        }
    }
}

/// The session whose job runs next, taken off the ring (`front`, the
/// ring's front, is already off it): `front` when its next job answers a
/// drag or a waiter; when it is a refinement, the session in the ring
/// whose run of refinements began earliest (`front` itself, or another,
/// taken off the ring, with `front` put at the back: it had its turn).
fn next_session(st: &mut State, front: String) -> String {
    let since_of = |st: &State, s: &str| st.queues.get(s).and_then(|q| q.front()).and_then(|j| j.2);
    let Some(mut earliest) = since_of(st, &front) else {
        return front;
    };
    let mut at = None;
    for (k, s) in st.ring.iter().enumerate() {
        if let Some(t) = since_of(st, s).filter(|&t| t < earliest) {
            (earliest, at) = (t, Some(k));
        }
    }
    match at.and_then(|k| st.ring.remove(k)) {
        Some(other) => {
            st.ring.push_back(front);
            other
        }
        None => front,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    /// Runs a job of session "blocker" that holds `s`'s one worker until
    /// the returned sender sends (or is dropped); returns once it runs.
    fn hold_the_worker(s: &Scheduler) -> mpsc::Sender<()> {
        let (gate_tx, gate_rx) = mpsc::channel::<()>();
        let (started_tx, started_rx) = mpsc::channel::<()>();
        s.submit("blocker", move || {
            let _ = started_tx.send(());
            let _ = gate_rx.recv();
        });
        started_rx.recv().expect("the worker runs the blocker");
        gate_tx
    }

    /// One worker, held busy while a greedy session queues many jobs and a
    /// quiet one queues one: the quiet job runs second, not after all of
    /// the greedy ones (the order is the property; no clock involved).
    #[test]
    fn a_session_with_one_job_does_not_wait_behind_a_greedy_one() {
        let s = Scheduler::new(1, None);
        let gate_tx = hold_the_worker(&s);
        let (order_tx, order_rx) = mpsc::channel::<String>();
        for k in 0..20 {
            let tx = order_tx.clone();
            s.submit("greedy", move || {
                let _ = tx.send(format!("greedy{k}"));
            });
        }
        let tx = order_tx.clone();
        s.submit("quiet", move || {
            let _ = tx.send("quiet".into());
        });
        assert_eq!(s.depth(), 21);
        assert_eq!(s.waiting(), 2);
        gate_tx.send(()).expect("gate");
        let order: Vec<String> = (0..21).map(|_| order_rx.recv().expect("job")).collect();
        assert_eq!(order[0], "greedy0");
        assert_eq!(order[1], "quiet", "{order:?}");
        // each session's own jobs keep their order
        let greedy: Vec<&String> = order.iter().filter(|j| j.starts_with('g')).collect();
        for (k, j) in greedy.iter().enumerate() {
            assert_eq!(**j, format!("greedy{k}"));
        }
    }

    /// Round-robin over many sessions: in every window of `S` consecutive
    /// jobs while all `S` sessions have work, each session runs exactly once.
    #[test]
    fn turns_go_round_the_sessions() {
        let s = Scheduler::new(1, None);
        let (gate_tx, gate_rx) = mpsc::channel::<()>();
        let (order_tx, order_rx) = mpsc::channel::<usize>();
        s.submit("blocker", move || {
            let _ = gate_rx.recv();
        });
        const S: usize = 5;
        const J: usize = 4;
        // submitted in bursts: all of session 0's jobs, then session 1's...
        for k in 0..S {
            for _ in 0..J {
                let tx = order_tx.clone();
                s.submit(&format!("s{k}"), move || {
                    let _ = tx.send(k);
                });
            }
        }
        gate_tx.send(()).expect("gate");
        let order: Vec<usize> = (0..S * J).map(|_| order_rx.recv().expect("job")).collect();
        for window in order.chunks(S) {
            let mut w = window.to_vec();
            w.sort_unstable();
            assert_eq!(w, (0..S).collect::<Vec<_>>(), "{order:?}");
        }
    }

    /// With one worker held busy: a refinement's turn goes to the
    /// refinement whose run began earliest, and a job answering a drag
    /// still runs when its turn comes.
    #[test]
    fn refinements_run_earliest_run_first_and_answers_keep_their_turn() {
        let s = Scheduler::new(1, None);
        let gate_tx = hold_the_worker(&s);
        let (order_tx, order_rx) = mpsc::channel::<&'static str>();
        let t0 = Instant::now();
        let later = |ms| t0 + std::time::Duration::from_millis(ms);
        // ring order: late, answer, early, middle
        for (session, since) in [
            ("late", Some(later(30))),
            ("answer", None),
            ("early", Some(t0)),
            ("middle", Some(later(10))),
        ] {
            let tx = order_tx.clone();
            let job = move || {
                let _ = tx.send(session);
            };
            match since {
                Some(t) => s.submit_refinement(session, t, job),
                None => s.submit(session, job),
            }
        }
        gate_tx.send(()).expect("gate");
        let order: Vec<&str> = (0..4).map(|_| order_rx.recv().expect("job")).collect();
        // late's turn goes to early, late goes to the back; the answer
        // then has its turn; middle's turn is its own (late began later)
        assert_eq!(order, ["early", "answer", "middle", "late"], "{order:?}");
    }

    /// A refinement made an answer (a drag came in behind it) has its
    /// turn in the ring, not after the earlier runs of refinements.
    #[test]
    fn a_refinement_a_drag_came_behind_takes_the_answers_turn() {
        let s = Scheduler::new(1, None);
        let gate_tx = hold_the_worker(&s);
        let (order_tx, order_rx) = mpsc::channel::<&'static str>();
        let t0 = Instant::now();
        // ring order: dragging (its refinement began last), settling
        for (session, since) in [
            ("dragging", t0 + std::time::Duration::from_millis(50)),
            ("settling", t0),
        ] {
            let tx = order_tx.clone();
            s.submit_refinement(session, since, move || {
                let _ = tx.send(session);
            });
        }
        s.answer_now("dragging");
        gate_tx.send(()).expect("gate");
        let order: Vec<&str> = (0..2).map(|_| order_rx.recv().expect("job")).collect();
        assert_eq!(order, ["dragging", "settling"], "{order:?}");
    }

    #[test]
    fn a_panicking_job_does_not_stop_the_worker() {
        let s = Scheduler::new(1, None);
        s.submit("a", || panic!("solver bug"));
        let (tx, rx) = mpsc::channel();
        s.submit("b", move || {
            let _ = tx.send(1);
        });
        assert_eq!(rx.recv(), Ok(1));
    }

    /// Waits until no job runs (a worker counts its job as running until
    /// the job has returned, after the job's own last message).
    fn wait_idle(s: &Scheduler) {
        while !s.shared.state.lock().running.is_empty() {
            std::thread::yield_now();
        }
    }

    /// The name of the thread a job submitted now runs on.
    fn thread_of_next_job(s: &Scheduler, session: &str) -> String {
        let (tx, rx) = mpsc::channel();
        s.submit(session, move || {
            let _ = tx.send(std::thread::current().name().map(str::to_owned));
        });
        rx.recv().expect("the job runs").unwrap_or_default()
    }

    /// A job that runs while another runs stays on its worker's own
    /// one-thread pool; a job that runs alone runs on its worker, whose
    /// parallel loops use rayon's shared pool (module docs). The thread's
    /// name tells which.
    #[test]
    fn a_job_beside_another_runs_on_its_workers_own_thread() {
        let s = Scheduler::new(2, None);
        let alone = thread_of_next_job(&s, "alone");
        assert!(alone.starts_with("dend-solver-"), "{alone}");
        assert_ne!(alone, "dend-solver-own");
        let (gate_tx, gate_rx) = mpsc::channel::<()>();
        let (started_tx, started_rx) = mpsc::channel::<()>();
        let (done_tx, done_rx) = mpsc::channel::<()>();
        s.submit("blocker", move || {
            let _ = started_tx.send(());
            let _ = gate_rx.recv();
            let _ = done_tx.send(());
        });
        started_rx.recv().expect("a worker runs the blocker");
        assert_eq!(thread_of_next_job(&s, "beside"), "dend-solver-own");
        gate_tx.send(()).expect("the blocker waits");
        done_rx.recv().expect("the blocker ends");
        wait_idle(&s);
        assert_ne!(thread_of_next_job(&s, "alone"), "dend-solver-own");
    }

    /// A session's next job taken while its previous one still runs (the
    /// session submits its next solve as soon as the previous job's result
    /// reaches it, before that job has returned) runs alone: it runs beside
    /// no other session's work.
    #[test]
    fn a_sessions_next_job_beside_its_own_previous_one_runs_alone() {
        let s = Scheduler::new(2, None);
        let (gate_tx, gate_rx) = mpsc::channel::<()>();
        let (started_tx, started_rx) = mpsc::channel::<()>();
        s.submit("one", move || {
            let _ = started_tx.send(());
            let _ = gate_rx.recv();
        });
        started_rx.recv().expect("a worker runs the first job");
        let next = thread_of_next_job(&s, "one");
        assert!(next.starts_with("dend-solver-"), "{next}");
        assert_ne!(next, "dend-solver-own");
        // another session's job beside it still stays on its own thread
        assert_eq!(thread_of_next_job(&s, "other"), "dend-solver-own");
        gate_tx.send(()).expect("the first job waits");
    }
}
