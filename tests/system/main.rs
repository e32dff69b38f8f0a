//! The slow system tests, one binary apart from `tests/it`: a multi-instance
//! failover behind HAProxy on PostgreSQL, named poses across a failover,
//! crash safety under SIGKILL, the posing suite's properties on the shared
//! meshes, and isolation tests that measure the process's resident memory
//! (so no other test may share their process).

mod crash_safety;
mod failover;
mod failover_fast;
mod failover_poses;
mod failover_support;
mod loadtest_fair;
mod posing_suite_even_pose;
mod posing_suite_monotone;
mod rolling_restart;
mod server_isolation;
mod takeover_grace;
