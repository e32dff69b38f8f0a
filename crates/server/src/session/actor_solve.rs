//! The solving side of the session actor: one solve at a time on the
//! solver scheduler (`crate::scheduler`), journaling the drags it carries first (a drag is
//! acknowledged only once journaled), and what comes back from the solver
//! and factor-build tasks.

use std::sync::Arc;
use std::time::Instant;

use super::{Actor, AfterBuild, Step};
use crate::session::error::SessionError;
use crate::session::shared::Internal;
use crate::session::types::{Event, Frame, PoseSnapshot};
use dend_protocol::ws::SessionState;
use dend_protocol::{FrameBody, FrameHeader};

impl Actor {
    /// Starts a solve on the solver scheduler when the session is ready and
    /// has something to do (new drags, waiters, or iterations left before
    /// it settles); the drags composed since the last solve are journaled
    /// first, in the same task.
    pub(super) fn maybe_start_solve(&mut self) {
        if self.solve.deformer.is_none() || self.state() != SessionState::Ready {
            return;
        }
        let Some(constraints) = self.set.constraints.clone() else {
            return;
        };
        if self.solve.dirty {
            self.solve.iters_since_change = 0;
        }
        let max_iters = self.inner.params.max_iters;
        let budget = if !self.flow.waiters.is_empty() {
            self.flow
                .waiters
                .iter()
                .map(|w| w.0)
                .max()
                .unwrap_or(max_iters)
                .max(1)
        } else if !self.shown.settled {
            let remaining = max_iters.saturating_sub(self.solve.iters_since_change);
            if remaining == 0 {
                self.shown.settled = true;
                self.commit_gesture();
                return;
            }
            self.opts.iters_per_frame.clamp(1, remaining)
        } else {
            return;
        };
        // a person is dragging (no one waits for a full solve and a drag
        // came within the quiet time, or waits for this solve: a drag that
        // waited behind a longer solve is still a drag): the coarse
        // corrections wait
        let hold = self.flow.waiters.is_empty()
            && self.solve.last_stream_drag.is_some_and(|t| {
                self.solve.drag_pending || t.elapsed() < crate::session::CORRECTION_QUIET
            });
        // drags faster than the full mesh can follow: coarse previews
        // answer them (`Deformer::preview`) and, between drags, refine
        // until they converge; then nothing runs until the next drag or
        // the end of the quiet time, when the full mesh refines (a fine
        // frame in the middle of a gesture would show a pose one fine
        // iteration from the preview's, and make the next preview start
        // from it)
        let threshold = self.opts.preview_above_ms;
        let preview = hold
            && threshold >= 0.0
            // (unknown before the first fine solve: previewed)
            && (self.solve.fine_iter_ms.is_nan() || self.solve.fine_iter_ms > threshold)
            && self.solve.deformer.as_ref().is_some_and(|d| d.can_preview());
        self.solve.wake_at = None;
        if let Some(due) = self.next_drag_due() {
            // the next drag of the stream would stop this refinement before
            // it finished an iteration: wait for it (or for a little past
            // when it was due, then refine)
            self.solve.wake_at = Some(due);
            return;
        }
        if preview && !self.solve.dirty && self.solve.preview_converged {
            self.solve.wake_at = self
                .solve
                .last_stream_drag
                .map(|t| t + crate::session::CORRECTION_QUIET);
            return;
        }
        // a refinement (no new drags, nobody waiting: between drags, over
        // the settle, or the solve towards a new constraint set) stops
        // early when a drag arrives (`Actor::interrupt`)
        self.solve.refining = !self.solve.drag_pending && self.flow.waiters.is_empty();
        self.solve.refining_since = if self.solve.refining {
            Some(self.solve.refining_since.unwrap_or_else(Instant::now))
        } else {
            None
        };
        self.flow.inflight = self.flow.waiters.drain(..).map(|w| w.1).collect();
        self.solve.inflight_drags = self.solve.drag_pending;
        self.solve.solves_started += 1;
        self.drags_taken();
        let Some(mut deformer) = self.solve.deformer.take() else {
            return;
        };
        self.solve
            .interrupt
            .store(false, std::sync::atomic::Ordering::Relaxed);
        deformer.set_interrupt(self.solve.refining.then(|| self.solve.interrupt.clone()));
        let journal = std::mem::take(&mut self.solve.journal);
        let (id, store, cache, fence) = (
            self.inner.id.clone(),
            self.opts.store.clone(),
            self.opts.cache.clone(),
            self.opts.fence,
        );
        let (rest, params, tx) = (
            self.inner.rest.clone(),
            self.inner.params,
            self.internal_tx.clone(),
        );
        let (applied_seq, generation, pose_epoch) = (
            self.shown.last_seq,
            self.set.generation,
            self.solve.pose_epoch,
        );
        let installed = self.set.factor.clone();
        let prepared = self.set.prepared.take();
        let refining = self.solve.refining;
        // other sessions' solves wait for a worker: a drag's step from the
        // rest pose skips its coarse start (`Deformer::hold_coarse_start`)
        let contended = self.opts.scheduler.waiting() > 0;
        let job = move || {
            let t0 = Instant::now();
            let appended = if journal.is_empty() {
                Ok(())
            } else {
                store.append(&id, fence, &journal)
            };
            // a drag is acknowledged only once journaled: when the append
            // fails, nothing is solved and the actor refuses the drags
            // (`journal_failed`: back to the last journaled targets)
            let (result, journal_failed) = match appended {
                Ok(()) => {
                    let step = (|| {
                        let factor = match installed {
                            Some(f) => f,
                            None => cache.get_or_build(&rest, &params, &constraints)?,
                        };
                        if let Some(levels) = prepared {
                            deformer.install_levels(levels, &factor);
                        }
                        // a refinement's corrections run: a drag stops them
                        // (`Actor::interrupt`) instead of waiting for them
                        deformer.hold_corrections(hold && !refining);
                        deformer.hold_coarse_start(hold && !refining && contended);
                        if preview {
                            let its = dend::deform::PREVIEW_ITERATIONS;
                            if let Some(r) = deformer.preview(&factor, &constraints, its)? {
                                return Ok((preview_report(&r), true));
                            }
                        }
                        Ok((deformer.step(&factor, &constraints, budget)?, false))
                    })();
                    (step, false)
                }
                Err(e) => (Err(SessionError::Store(e)), true),
            };
            let seconds = t0.elapsed().as_secs_f64();
            let body = FrameBody::from_pose(deformer.shown_pose());
            let (result, preview) = match result {
                Ok((report, preview)) => (Ok(report), preview),
                Err(e) => (Err(e), false),
            };
            let _ = tx.send(Internal::Solved {
                deformer,
                result,
                preview,
                body,
                seconds,
                applied_seq,
                journal_failed,
                constraints,
                generation,
                pose_epoch,
            });
        };
        match self.solve.refining_since {
            Some(since) => self
                .opts
                .scheduler
                .submit_refinement(&self.inner.id, since, job),
            None => self.opts.scheduler.submit(&self.inner.id, job),
        }
    }

    /// [`refinement_wait`] for the solve about to start, `None` when it is
    /// not a refinement (new drags or waiters) or no fine iteration has
    /// been timed yet.
    fn next_drag_due(&self) -> Option<std::time::Instant> {
        // (NaN, before a fine solve was timed: none)
        let timed = self.solve.fine_iter_ms > 0.0;
        if self.solve.dirty || self.solve.drag_pending || !self.flow.waiters.is_empty() || !timed {
            return None;
        }
        let iteration = std::time::Duration::from_secs_f64(self.solve.fine_iter_ms * 1e-3);
        refinement_wait(
            std::time::Instant::now(),
            self.solve.last_stream_drag?,
            self.solve.drag_gap?,
            iteration,
        )
    }

    pub(super) fn on_internal(&mut self, msg: Internal) {
        match msg {
            Internal::Stage { generation, stage } => {
                if generation == self.set.generation && self.state() == SessionState::Building {
                    self.inner.shared.lock().build_stage = Some(stage);
                    let _ = self.inner.events.send(Event::BuildProgress { stage });
                }
            }
            Internal::LevelsBuilt {
                generation,
                levels,
                seconds,
            } => {
                if !levels.is_empty() {
                    self.opts.observer.levels_ready(seconds);
                }
                if generation == self.set.generation {
                    self.set.prepared = Some(levels);
                }
            }
            Internal::Built {
                generation,
                result,
                seconds,
            } => {
                if generation == self.set.generation {
                    self.inner.shared.lock().build_stage = None;
                }
                if result.is_ok() {
                    self.opts.observer.factor_ready(seconds);
                }
                if generation != self.set.generation {
                    return;
                }
                self.shown.revision += 1;
                match result {
                    Ok(factor) => {
                        self.set.factor = Some(factor);
                        let after = self.phase.after_build();
                        self.go(Step::Built);
                        if after == Some(AfterBuild::Solve) {
                            // solve towards the set's targets; the settled
                            // result becomes a history entry
                            self.solve.dirty = true;
                            self.shown.settled = false;
                            self.history.uncommitted = true;
                        }
                        self.sync_shared();
                        let _ = self.inner.events.send(Event::Ready {
                            revision: self.shown.revision,
                        });
                        self.apply_queued();
                    }
                    Err(e) => {
                        self.go(Step::BuildFailed);
                        self.sync_shared();
                        let e = Arc::new(e);
                        self.refuse_queued(|| SessionError::Shared(e.clone()));
                        self.fail_revival(&e);
                        let _ = self.inner.events.send(Event::Error(e));
                        let _ = self.inner.events.send(Event::State);
                    }
                }
            }
            Internal::Solved {
                deformer,
                result,
                preview,
                body,
                seconds,
                applied_seq,
                journal_failed,
                constraints,
                generation,
                pose_epoch,
            } => {
                self.solve.refining = false;
                self.solve.inflight_drags = false;
                self.solve.solves_done += 1;
                if pose_epoch != self.solve.pose_epoch {
                    // an undo, redo, reset or restore replaced the pose while
                    // this solve ran: its pose and frame are not the
                    // session's; the deformer takes the current pose, and
                    // the drags it carried were journaled (acknowledged)
                    let mut deformer = deformer;
                    if let Err(e) = deformer.set_pose(self.shown.pose.to_vec()) {
                        tracing::error!(session = %self.inner.id, error = %e, "restoring the pose after a solve");
                    }
                    self.solve.deformer = Some(deformer);
                    if generation == self.set.generation && !journal_failed {
                        self.shown.applied_seq = applied_seq;
                    }
                    let header = self.header();
                    for w in std::mem::take(&mut self.flow.inflight) {
                        let _ = w.send(Ok(self.snapshot_for(&header)));
                    }
                    drop((result, body, constraints, seconds));
                    self.sync_shared();
                    return;
                }
                if !preview && matches!(&result, Ok(r) if r.interrupted && r.iterations == 0) {
                    // a refinement stopped by a drag before its first
                    // iteration ended: the pose is the last frame's, and
                    // the drag's solve starts now
                    self.solve.deformer = Some(deformer);
                    return;
                }
                self.shown.pose = Arc::new(deformer.shown_pose().to_vec());
                self.solve.deformer = Some(deformer);
                if generation == self.set.generation {
                    if journal_failed {
                        self.journal_failed(&result);
                    } else {
                        self.shown.applied_seq = applied_seq;
                        self.set.confirmed = Some(constraints);
                    }
                }
                self.shown.level = if preview {
                    dend_protocol::LEVEL_COARSE
                } else {
                    dend_protocol::LEVEL_FULL
                };
                let error = match result {
                    Ok(report) if preview => {
                        self.solve.preview_converged = report.converged;
                        // a picture of where the drag goes: not converged,
                        // no fine objective, never settled
                        self.shown.converged = false;
                        self.shown.objective = f64::NAN;
                        self.shown.settled = false;
                        None
                    }
                    Ok(report) => {
                        if report.iterations > 0 && !report.interrupted {
                            self.solve.fine_iter_ms = (seconds * 1e3 - report.coarse_ms).max(0.0)
                                / report.iterations as f64;
                        }
                        self.solve.iters_since_change += report.iterations;
                        self.shown.converged = report.converged;
                        self.shown.objective = report.objective;
                        self.opts
                            .observer
                            .solved(report.iterations, seconds, report.converged);
                        let done = report.converged
                            || self.solve.iters_since_change >= self.inner.params.max_iters;
                        self.shown.settled = !self.solve.dirty && (done || report.diverged);
                        None
                    }
                    Err(e) => {
                        // (drags received during the failed solve get a
                        // solve of their own: a constraint edit waits for it)
                        self.shown.settled = !self.solve.dirty;
                        Some(Arc::new(e))
                    }
                };
                self.shown.revision += 1;
                let header = self.header();
                let bytes = body.finish(&header);
                self.frames_tx.send_replace(Some(Frame { header, bytes }));
                if generation == self.set.generation && !journal_failed && self.shown.settled {
                    // the revived pose is the settled one: an iterate on
                    // the way there is not the pose the acknowledged drags
                    // led to, and is not served
                    self.end_revival(&header);
                }
                for w in std::mem::take(&mut self.flow.inflight) {
                    let _ = w.send(match &error {
                        None => Ok(self.snapshot_for(&header)),
                        Some(e) => Err(SessionError::Shared(e.clone())),
                    });
                }
                if let Some(e) = error {
                    let _ = self.inner.events.send(Event::Error(e));
                }
                if self.shown.settled {
                    self.commit_gesture();
                }
                self.sync_shared();
            }
        }
    }

    /// The journal append of a solve failed: none of its drags, nor the
    /// ones composed since, is acknowledged, and the targets go back to
    /// the last journaled ones (a drag is applied only once journaled, so
    /// the live state never holds what a revival would not). Clients get
    /// the error (HTTP 503 `store_unavailable`, or an `error` event with
    /// frames still acknowledging the previous `seq`) and send again. A
    /// fenced append stops the session instead.
    pub(super) fn journal_failed(
        &mut self,
        result: &Result<dend::deform::StepReport, SessionError>,
    ) {
        if let Err(SessionError::Store(e)) = result {
            self.on_store_error(e);
        }
        self.set.constraints = self.set.confirmed.clone();
        self.solve.journal.clear();
        self.shown.last_seq = self.shown.applied_seq;
        self.drags_taken();
        for (_, w) in self.flow.waiters.drain(..) {
            let _ = w.send(Err(match result {
                Err(SessionError::Store(e)) => SessionError::Store(e.clone()),
                _ => SessionError::Closed,
            }));
        }
    }

    pub(super) fn snapshot_for(&self, h: &FrameHeader) -> PoseSnapshot {
        PoseSnapshot {
            header: *h,
            positions: self.shown.pose.clone(),
        }
    }
}

/// The step report of a frame that shows a coarse preview: no fine
/// iteration, no fine objective, the preview's coarse work.
fn preview_report(r: &dend::deform::PreviewReport) -> dend::deform::StepReport {
    dend::deform::StepReport {
        iterations: 0,
        last_update: f64::NAN,
        // the coarse problem's (the frame itself is never converged)
        converged: r.converged,
        diverged: false,
        objective: f64::NAN,
        initial_objective: f64::NAN,
        coarse_iterations: r.iterations,
        coarse_ms: r.ms,
        coarse_work: r.work,
        interrupted: false,
    }
}

/// How long a refinement waits for the next drag of a stream: drags came
/// `gap` apart, the last at `last`, so the next is due at `last + gap`. A
/// refinement started at `now` would be stopped by it before finishing
/// one fine iteration (`iteration`) when it is due sooner than that: it
/// then waits, until half a gap past when the drag was due, and starts
/// if none came. Returns that time, or `None` to start now.
pub(super) fn refinement_wait(
    now: std::time::Instant,
    last: std::time::Instant,
    gap: std::time::Duration,
    iteration: std::time::Duration,
) -> Option<std::time::Instant> {
    let due = last + gap;
    let until = due + gap / 2;
    (due.saturating_duration_since(now) < iteration && now < until).then_some(until)
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use super::refinement_wait;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn a_refinement_waits_only_for_a_drag_due_within_one_iteration() {
        let last = Instant::now();
        let gap = 8 * MS;
        // 6 ms after the last drag, the next due in 2 ms, an iteration 5 ms:
        // the refinement would be stopped, so it waits until 12 ms
        assert_eq!(
            refinement_wait(last + 6 * MS, last, gap, 5 * MS),
            Some(last + 12 * MS)
        );
        // with a 1 ms iteration it finishes one first: it starts now
        assert_eq!(refinement_wait(last + 6 * MS, last, gap, MS), None);
        // drags 100 ms apart (a person dragging slowly): it starts now
        assert_eq!(refinement_wait(last + 6 * MS, last, 100 * MS, 5 * MS), None);
        // the drag is overdue but within half a gap: still waiting
        assert_eq!(
            refinement_wait(last + 10 * MS, last, gap, 5 * MS),
            Some(last + 12 * MS)
        );
        // half a gap past due: the stream has paused, it starts
        assert_eq!(refinement_wait(last + 12 * MS, last, gap, 5 * MS), None);
        assert_eq!(refinement_wait(last + 50 * MS, last, gap, 5 * MS), None);
    }
}
