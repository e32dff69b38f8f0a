//! Fair under overload, in CI (docs/reliability.md): `dend loadtest` with more
//! dragging sessions than two solver threads can serve at once, its own
//! checks on: drag→frame maximum ≤ 2 s and p99 ≤ 1 s, every session's
//! median within 3× the overall median (the scheduler's round-robin), and
//! new sessions opened during the drags refused with 503 `overloaded`
//! (admission control). The figure is 40 sessions × 500 drags on
//! a 100×100 grid (`scripts/loadtest-cluster.sh`, docs/reliability.md);
//! CI runs 16 sessions × 60 drags on a 30×30 grid, in the dev profile, with
//! the admission limit lowered to 8 waiting sessions so that it is reached.

use std::process::Command;

#[test]
fn sixteen_sessions_on_two_solver_threads_are_served_fairly_and_admission_refuses_more() {
    let out = Command::new(env!("CARGO_BIN_EXE_dend"))
        .args([
            "loadtest",
            "--sessions",
            "16",
            "--drags",
            "60",
            "--grid",
            "30",
        ])
        .args(["--solver-threads", "2", "--admission-waiting-sessions", "8"])
        .args(["--extra-sessions", "4", "--check-refused", "1"])
        .args(["--check-max-ms", "2000", "--check-p99-ms", "1000"])
        .args(["--check-fairness", "3"])
        .output()
        .expect("run dend loadtest");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("{stdout}");
    assert!(
        out.status.success(),
        "the load test's checks failed:\n{stdout}\n{stderr}"
    );
    assert!(
        stdout.contains("worst session / overall median"),
        "{stdout}"
    );
}

/// A session's later gestures (`--gestures`): along the arc, back, and
/// along again, each settled before the next. Every gesture's drags are
/// acknowledged under their own `seq` (a gesture that reused the first's
/// would wait for ever for its acknowledgements, or end at once), and the
/// report gives one settle per gesture.
#[test]
fn a_session_drags_three_gestures_along_the_path_and_back() {
    let out = Command::new(env!("CARGO_BIN_EXE_dend"))
        .args(["loadtest", "--drags", "12", "--grid", "20", "--path", "arc"])
        .args(["--gestures", "3"])
        .output()
        .expect("run dend loadtest");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let line = stdout
        .lines()
        .find(|l| l.contains("settle by gesture"))
        .unwrap_or_else(|| panic!("no settle by gesture:\n{stdout}"));
    for g in ["1: ", "2: ", "3: "] {
        assert!(line.contains(g), "{line}");
    }
    assert!(stdout.contains("converged 1/1"), "{stdout}");
}
