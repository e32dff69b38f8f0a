//! Interrupted steps ([`Deformer::set_interrupt`]): a step stopped by the
//! flag leaves a state from which the iteration goes on as if it had not
//! run.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use super::test_util::creature_moved;
use crate::deform::{Deformer, Factor, Galerkin, Params, Rest};
use crate::mesh::gen::{generate, Shape, ShapeSpec};

/// On the generated creature, with the coarse problems' corrections (two
/// levels: every 5 iterations) and with Galerkin ones (after every
/// iteration), `first` iterations, a step with the flag raised, then 9
/// more give the same pose, bit for bit, as `first` and 9 without it; the
/// interrupted step reports no iteration and leaves the pose as it was.
#[test]
fn an_interrupted_step_changes_nothing() {
    for (galerkin, first) in [(None, 7), (Some(Galerkin::default()), 2)] {
        interrupted_step_changes_nothing(galerkin, first);
    }
}

fn interrupted_step_changes_nothing(galerkin: Option<Galerkin>, first_its: usize) {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    let c = creature_moved(&mesh);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let flag = Arc::new(AtomicBool::new(false));
    let run = |interrupt: bool| {
        let mut d = Deformer::new(rest.clone(), params);
        d.set_galerkin(galerkin);
        d.set_interrupt(Some(flag.clone()));
        flag.store(false, Ordering::Relaxed);
        let first = d.step(&f, &c, first_its).unwrap();
        assert!(!first.interrupted && first.iterations == first_its);
        if interrupt {
            let before = d.pose().to_vec();
            flag.store(true, Ordering::Relaxed);
            let r = d.step(&f, &c, 5).unwrap();
            assert!(r.interrupted, "{r:?}");
            assert_eq!(r.iterations, 0);
            assert_eq!(r.objective, first.objective);
            assert_eq!(d.pose(), &before[..]);
            flag.store(false, Ordering::Relaxed);
        }
        let mut last = d.step(&f, &c, 9).unwrap();
        assert!(!last.interrupted);
        last.coarse_ms = 0.0; // (wall time)
        (last, d.pose().to_vec())
    };
    let (plain, plain_pose) = run(false);
    let (stopped, stopped_pose) = run(true);
    assert!(
        plain.coarse_iterations > 0,
        "{galerkin:?}: corrections ran: {plain:?}"
    );
    assert_eq!(plain, stopped);
    assert_eq!(plain_pose, stopped_pose);
}

/// A flag raised before a step from the rest pose stops it before its
/// first iteration ends, and without a flag the same deformer then
/// reaches the pose of one that never had one.
#[test]
fn a_step_from_rest_stopped_at_once_then_resumed_reaches_the_same_pose() {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    // (targets off the rest positions: towards those a step from the rest
    // pose is converged at once, `rest_start_tests.rs`)
    let c = creature_moved(&mesh);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut plain = Deformer::new(rest.clone(), params);
    let want = plain.step(&f, &c, 40).unwrap();
    let mut d = Deformer::new(rest, params);
    d.set_interrupt(Some(Arc::new(AtomicBool::new(true))));
    let r = d.step(&f, &c, 40).unwrap();
    assert!(r.interrupted && r.iterations == 0, "{r:?}");
    d.set_interrupt(None);
    let got = d.step(&f, &c, 40).unwrap();
    assert_eq!(got.iterations, want.iterations);
    assert_eq!(d.pose(), plain.pose());
}
