//! The session actor's phase: where its constraint set is (no set yet,
//! the factor being built, ready, failed), whether a revival is still on
//! its way to the journaled pose, and whether the lease is lost. Every
//! change of phase is a [`Step`] taken through [`Phase::next`], the one
//! place that says which steps are legal from where.
//!
//! ```text
//!   Empty ──Install──▶ Building{then, revival: false} ──Built──▶ Ready
//!     │                    ▲      │                                │
//!     │                    │      └──BuildFailed──▶ Failed ◀────┐  │
//!     │                    └─────────Install──────────┴─────────┼──┘
//!     └──Revive──▶ Building{Solve, revival: true} ──Built──▶ Reviving ──Settled──▶ Ready
//!                          │                                     │
//!                          └──BuildFailed──▶ Failed{revival} ◀───┘ (Install: back to Building)
//!   any ──Fenced──▶ Draining (the actor ends)
//! ```
//!
//! Whether a solve is running (the deformer away on the scheduler) and
//! whether the pose has settled are the solve's own state
//! (`actor_solve.rs`): a solve runs only in `Ready` or `Reviving`.

use dend_protocol::ws::SessionState;

/// What the session does once a constraint set's factor is ready.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum AfterBuild {
    /// Solve towards the set's targets; the settled pose becomes a history
    /// entry (a new set, a revival).
    Solve,
    /// Keep the pose as it is (undo, redo and reset to another set).
    Keep,
}

/// The phase of a session actor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Phase {
    /// No constraint set yet (state `empty`).
    Empty,
    /// A constraint set's factor is being looked up or built (state
    /// `building`); drags wait for it. `then`: what follows; `revival`:
    /// a revival has not settled yet, so pose reads wait.
    Building { then: AfterBuild, revival: bool },
    /// A revived session's factor is ready and its solve towards the
    /// journaled drags has not settled: the pose is the checkpoint's, or
    /// an iterate on the way, and reads wait for the settled one (state
    /// `ready`).
    Reviving,
    /// The factor is ready: drags are solved, reads served (state `ready`).
    Ready,
    /// The factor build failed (state `failed`); another constraint set
    /// may be installed. `revival`: the session has no pose of its own to
    /// serve (the revival never settled).
    Failed { revival: bool },
    /// A store write was fenced: another instance owns the session, and
    /// this actor ends once the command at hand is done. `state` and
    /// `revival`: the phase's before, which the session keeps showing (and
    /// its reads keep following) until it closes.
    Draining { state: SessionState, revival: bool },
}

/// A change of phase.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Step {
    /// A constraint set is installed; its factor is looked up or built.
    Install(AfterBuild),
    /// A stored set is re-opened with the recovered pose and targets: a
    /// revival starts (its factor, then its solve).
    Revive,
    /// The installed set's factor is ready.
    Built,
    /// The installed set's factor could not be built.
    BuildFailed,
    /// A solve of the installed set settled (its drags journaled).
    Settled,
    /// A store write was fenced: the lease is lost.
    Fenced,
}

/// A step that is not legal from a phase (a bug in the actor, or a
/// draining actor finishing its last command).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("no step {step:?} from phase {from:?}")]
pub(super) struct IllegalStep {
    pub(super) from: Phase,
    pub(super) step: Step,
}

/// What a pose read gets in a phase.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Read {
    /// The current pose.
    Serve,
    /// Nothing yet: the revival's settled pose, once there is one.
    Wait,
    /// A refusal: the revival failed, there is no pose of the session's.
    Refuse,
}

impl Phase {
    /// The phase after `step`, or why `step` is not legal here.
    pub(super) fn next(self, step: Step) -> Result<Phase, IllegalStep> {
        use Phase::{Building, Draining, Empty, Failed, Ready, Reviving};
        let illegal = Err(IllegalStep { from: self, step });
        Ok(match (self, step) {
            // nothing follows the end but the end
            (Draining { .. }, Step::Fenced) => self,
            (Draining { .. }, _) => return illegal,
            (_, Step::Fenced) => Draining {
                state: self.state(),
                revival: self.revival(),
            },
            (_, Step::Revive) => Building {
                then: AfterBuild::Solve,
                revival: true,
            },
            // a set installed before a revival settled: reads still wait
            // for a settled pose (of the new set's solve)
            (Empty | Building { .. } | Reviving | Ready | Failed { .. }, Step::Install(then)) => {
                Building {
                    then,
                    revival: self.revival(),
                }
            }
            (Building { revival, .. }, Step::Built) => {
                if revival {
                    Reviving
                } else {
                    Ready
                }
            }
            (Building { revival, .. }, Step::BuildFailed) => Failed { revival },
            (Reviving | Ready, Step::Settled) => Ready,
            (Empty | Reviving | Ready | Failed { .. }, Step::Built | Step::BuildFailed)
            | (Empty | Building { .. } | Failed { .. }, Step::Settled) => return illegal,
        })
    }

    /// The state clients see.
    pub(super) fn state(self) -> SessionState {
        match self {
            Phase::Empty => SessionState::Empty,
            Phase::Building { .. } => SessionState::Building,
            Phase::Reviving | Phase::Ready => SessionState::Ready,
            Phase::Failed { .. } => SessionState::Failed,
            Phase::Draining { state, .. } => state,
        }
    }

    /// Whether a revival has not settled yet.
    pub(super) fn revival(self) -> bool {
        matches!(
            self,
            Phase::Building { revival: true, .. }
                | Phase::Reviving
                | Phase::Failed { revival: true }
                | Phase::Draining { revival: true, .. }
        )
    }

    /// What follows the factor build under way (`None`: none is).
    pub(super) fn after_build(self) -> Option<AfterBuild> {
        match self {
            Phase::Building { then, .. } => Some(then),
            _ => None,
        }
    }

    /// What a pose read gets now.
    pub(super) fn read(self) -> Read {
        match (self.revival(), self.state()) {
            (true, SessionState::Failed) => Read::Refuse,
            (true, _) => Read::Wait,
            (false, _) => Read::Serve,
        }
    }

    /// Whether the lease is lost and the actor ends.
    pub(super) fn draining(self) -> bool {
        matches!(self, Phase::Draining { .. })
    }
}

#[cfg(test)]
mod tests {
    use super::{AfterBuild, IllegalStep, Phase, Read, Step};
    use dend_protocol::ws::SessionState;

    const SOLVE: Step = Step::Install(AfterBuild::Solve);
    const KEEP: Step = Step::Install(AfterBuild::Keep);

    /// Every phase, each variant with each of its values.
    fn phases() -> Vec<Phase> {
        let mut all = vec![Phase::Empty, Phase::Reviving, Phase::Ready];
        for revival in [false, true] {
            for then in [AfterBuild::Solve, AfterBuild::Keep] {
                all.push(Phase::Building { then, revival });
            }
            all.push(Phase::Failed { revival });
        }
        for state in [
            SessionState::Empty,
            SessionState::Building,
            SessionState::Ready,
            SessionState::Failed,
        ] {
            for revival in [false, true] {
                all.push(Phase::Draining { state, revival });
            }
        }
        all
    }

    const STEPS: [Step; 7] = [
        SOLVE,
        KEEP,
        Step::Revive,
        Step::Built,
        Step::BuildFailed,
        Step::Settled,
        Step::Fenced,
    ];

    fn run(from: Phase, steps: &[Step]) -> Result<Phase, IllegalStep> {
        steps.iter().try_fold(from, |p, &s| p.next(s))
    }

    #[test]
    fn a_new_set_builds_then_is_ready_or_failed() {
        let building = Phase::Empty.next(SOLVE).unwrap();
        assert_eq!(building.state(), SessionState::Building);
        assert_eq!(building.after_build(), Some(AfterBuild::Solve));
        assert_eq!(building.read(), Read::Serve);
        assert_eq!(building.next(Step::Built), Ok(Phase::Ready));
        assert_eq!(
            building.next(Step::BuildFailed),
            Ok(Phase::Failed { revival: false })
        );
        // undo to another set keeps the pose while its factor builds
        assert_eq!(
            run(Phase::Empty, &[SOLVE, Step::Built, KEEP]).map(Phase::after_build),
            Ok(Some(AfterBuild::Keep))
        );
        // a failed set is left by installing another
        assert_eq!(
            run(
                Phase::Empty,
                &[SOLVE, Step::BuildFailed, SOLVE, Step::Built]
            ),
            Ok(Phase::Ready)
        );
    }

    #[test]
    fn reads_wait_from_a_revival_until_its_solve_settles() {
        let steps = [Step::Revive, Step::Built];
        let reviving = run(Phase::Empty, &steps).unwrap();
        assert_eq!(reviving, Phase::Reviving);
        // clients see a ready session (drags are taken) but reads wait
        assert_eq!(reviving.state(), SessionState::Ready);
        assert_eq!(reviving.read(), Read::Wait);
        assert_eq!(reviving.next(Step::Settled), Ok(Phase::Ready));
        assert_eq!(Phase::Ready.next(Step::Settled), Ok(Phase::Ready));
        // a set installed before the revival settled: still waiting, also
        // while the new set builds, until its own solve settles
        let again = run(reviving, &[KEEP]).unwrap();
        assert_eq!(again.read(), Read::Wait);
        assert_eq!(run(again, &[Step::Built, Step::Settled]), Ok(Phase::Ready));
        // a revival whose factor fails has no pose to serve: refused, until
        // another set is installed and settles
        let failed = run(Phase::Empty, &[Step::Revive, Step::BuildFailed]).unwrap();
        assert_eq!(failed.read(), Read::Refuse);
        assert_eq!(failed.state(), SessionState::Failed);
        assert_eq!(run(failed, &[SOLVE]).map(Phase::read), Ok(Read::Wait));
        assert_eq!(
            run(failed, &[SOLVE, Step::Built, Step::Settled]).map(Phase::read),
            Ok(Read::Serve)
        );
        // a revival may start over any phase but a draining one
        for p in phases() {
            assert_eq!(p.next(Step::Revive).is_ok(), !p.draining(), "{p:?}");
        }
    }

    #[test]
    fn a_fenced_write_drains_from_every_phase_and_nothing_leaves_draining() {
        for p in phases() {
            let d = p.next(Step::Fenced).unwrap();
            assert!(d.draining(), "{p:?}");
            // the session keeps showing its state, and reads keep waiting
            // for a revival, until it closes
            assert_eq!(d.state(), p.state(), "{p:?}");
            assert_eq!(d.read(), p.read(), "{p:?}");
            assert_eq!(d.next(Step::Fenced), Ok(d));
            for s in STEPS.into_iter().filter(|&s| s != Step::Fenced) {
                assert_eq!(d.next(s), Err(IllegalStep { from: d, step: s }));
            }
        }
    }

    #[test]
    fn build_results_come_only_while_building_and_settles_only_when_ready() {
        for p in phases() {
            let building = matches!(p, Phase::Building { .. });
            let ready = matches!(p, Phase::Ready | Phase::Reviving);
            for s in [Step::Built, Step::BuildFailed] {
                assert_eq!(p.next(s).is_ok(), building, "{p:?} {s:?}");
            }
            assert_eq!(p.next(Step::Settled).is_ok(), ready, "{p:?}");
            assert_eq!(p.after_build().is_some(), building, "{p:?}");
            // every phase but draining takes a new set
            for s in [SOLVE, KEEP] {
                assert_eq!(p.next(s).is_ok(), !p.draining(), "{p:?} {s:?}");
            }
        }
    }

    #[test]
    fn the_state_shown_and_reads_follow_the_phase_alone() {
        // an independent table of what each phase shows and serves
        for p in phases() {
            let (state, read) = match p {
                Phase::Empty => (SessionState::Empty, Read::Serve),
                Phase::Building { revival, .. } => (
                    SessionState::Building,
                    if revival { Read::Wait } else { Read::Serve },
                ),
                Phase::Reviving => (SessionState::Ready, Read::Wait),
                Phase::Ready => (SessionState::Ready, Read::Serve),
                Phase::Failed { revival } => (
                    SessionState::Failed,
                    if revival { Read::Refuse } else { Read::Serve },
                ),
                Phase::Draining { state, revival } => (
                    state,
                    match (revival, state) {
                        (false, _) => Read::Serve,
                        (true, SessionState::Failed) => Read::Refuse,
                        (true, _) => Read::Wait,
                    },
                ),
            };
            assert_eq!((p.state(), p.read()), (state, read), "{p:?}");
        }
    }
}
