//! The lease rule, written once for every backend: who may take a
//! session's lease, who keeps it, which writes it fences. Pure functions of
//! what a backend read of the lease row (the memory store's map entry, the
//! SQLite or PostgreSQL row read in the backend's transaction); the backend
//! writes what they decide. The SQL backends' renewal, release and
//! hand-over queries filter rows with the same predicates ([`holds`],
//! [`wants_handoff`]) in their `WHERE` clauses.
//!
//! A lease row is never deleted while its session exists: releasing it only
//! expires it, so revisions keep growing and a fence handed out once can
//! never become valid again.

use crate::store::types::{Fence, LeaseGrant, StoreError, NO_FENCE};

/// Where a lease row's expiry stands, measured by the backend's clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Expiry {
    /// Released by its owner (or a placeholder row that was never held).
    Released,
    /// Held, but its time ran out without a renewal (its owner is gone or
    /// frozen).
    Expired,
    /// Held for another `left_ms` milliseconds.
    Live {
        /// Time left.
        left_ms: u64,
    },
}

impl Expiry {
    /// From a remaining time in milliseconds (`None`: released).
    pub(super) fn from_left_ms(left_ms: Option<i64>) -> Expiry {
        match left_ms {
            None => Expiry::Released,
            Some(ms) if ms > 0 => Expiry::Live {
                left_ms: ms.unsigned_abs(),
            },
            Some(_) => Expiry::Expired,
        }
    }
}

/// What a backend read of a session's lease row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct LeaseRow<'a> {
    /// The instance that holds (or last held) the lease.
    pub owner: &'a str,
    /// Its revision, the fence of its holder's writes.
    pub revision: Fence,
    /// Whether it is still held.
    pub expiry: Expiry,
}

/// The decision on `owner`'s request for the lease whose row is `current`
/// (`None`: the session never had one):
/// - held by another instance and live: [`LeaseGrant::HeldBy`]; the
///   backend records `owner` as wanting it (the holder hands it over at its
///   next renewal, see [`wants_handoff`]) and changes nothing else;
/// - otherwise (no row, released, expired, or already `owner`'s):
///   [`LeaseGrant::Granted`] with the next revision (1 for a first lease),
///   `taken_over` when it was another instance's and not released (an
///   expired owner's); the backend writes `owner`, that revision, an expiry
///   one lifetime from now and clears the hand-over request.
pub(super) fn acquire(current: Option<LeaseRow<'_>>, owner: &str) -> LeaseGrant {
    match current {
        Some(LeaseRow {
            owner: holder,
            expiry: Expiry::Live { left_ms },
            ..
        }) if holder != owner => LeaseGrant::HeldBy {
            owner: holder.to_owned(),
            expires_in_ms: left_ms,
        },
        Some(row) => LeaseGrant::Granted {
            revision: row.revision + 1,
            taken_over: row.owner != owner && row.expiry != Expiry::Released,
        },
        None => LeaseGrant::Granted {
            revision: 1,
            taken_over: false,
        },
    }
}

/// Whether `owner` at `revision` still holds the lease of `row`: a
/// renewal or release by anyone else (a later revision took it over)
/// changes nothing, and a renewal that fails tells the instance it lost
/// the session. An expired lease that nobody took yet is renewed.
pub(super) fn holds(row: LeaseRow<'_>, owner: &str, revision: Fence) -> bool {
    row.owner == owner && row.revision == revision
}

/// Whether `owner` should hand the session of `row` over: another instance
/// asked for it (`wanted`) while `owner` holds it live.
pub(super) fn wants_handoff(row: LeaseRow<'_>, wanted: bool, owner: &str) -> bool {
    wanted && row.owner == owner && matches!(row.expiry, Expiry::Live { .. })
}

/// Admits a write of session `id` fenced by `fence` only when `fence` is
/// the current lease revision ([`NO_FENCE`] skips the check: the
/// single-instance mode); `current` is the lease row's owner and revision.
pub(super) fn check_fence(
    id: &str,
    fence: Fence,
    current: Option<(&str, Fence)>,
) -> Result<(), StoreError> {
    match current {
        _ if fence == NO_FENCE => Ok(()),
        Some((_, revision)) if revision == fence => Ok(()),
        other => Err(StoreError::Fenced {
            session: id.to_owned(),
            fence,
            current: other.map(|r| r.1),
            owner: other.map(|r| r.0.to_owned()),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(owner: &str, revision: Fence, expiry: Expiry) -> LeaseRow<'_> {
        LeaseRow {
            owner,
            revision,
            expiry,
        }
    }

    const LIVE: Expiry = Expiry::Live { left_ms: 1500 };

    #[test]
    fn a_first_lease_is_revision_one_and_no_takeover() {
        assert_eq!(
            acquire(None, "a"),
            LeaseGrant::Granted {
                revision: 1,
                taken_over: false
            }
        );
    }

    #[test]
    fn a_live_lease_of_another_instance_is_refused_with_its_time_left() {
        assert_eq!(
            acquire(Some(row("b", 4, LIVE)), "a"),
            LeaseGrant::HeldBy {
                owner: "b".into(),
                expires_in_ms: 1500
            }
        );
    }

    #[test]
    fn the_holder_takes_its_own_lease_again_at_the_next_revision() {
        for expiry in [LIVE, Expiry::Expired, Expiry::Released] {
            assert_eq!(
                acquire(Some(row("a", 4, expiry)), "a"),
                LeaseGrant::Granted {
                    revision: 5,
                    taken_over: false
                },
                "{expiry:?}"
            );
        }
    }

    #[test]
    fn an_expired_lease_of_another_instance_is_taken_over() {
        assert_eq!(
            acquire(Some(row("b", 4, Expiry::Expired)), "a"),
            LeaseGrant::Granted {
                revision: 5,
                taken_over: true
            }
        );
    }

    #[test]
    fn a_released_lease_is_handed_over_without_a_takeover() {
        assert_eq!(
            acquire(Some(row("b", 4, Expiry::Released)), "a"),
            LeaseGrant::Granted {
                revision: 5,
                taken_over: false
            }
        );
        // the PostgreSQL placeholder row (owner '', revision 0, released)
        assert_eq!(
            acquire(Some(row("", 0, Expiry::Released)), "a"),
            LeaseGrant::Granted {
                revision: 1,
                taken_over: false
            }
        );
    }

    #[test]
    fn expiry_reads_time_left() {
        assert_eq!(Expiry::from_left_ms(None), Expiry::Released);
        assert_eq!(Expiry::from_left_ms(Some(0)), Expiry::Expired);
        assert_eq!(Expiry::from_left_ms(Some(-30)), Expiry::Expired);
        assert_eq!(Expiry::from_left_ms(Some(7)), Expiry::Live { left_ms: 7 });
    }

    #[test]
    fn only_the_current_owner_and_revision_renew_or_release() {
        let r = row("a", 4, LIVE);
        assert!(holds(r, "a", 4));
        assert!(!holds(r, "a", 3), "an older revision of the same owner");
        assert!(!holds(r, "b", 4), "another owner");
        assert!(
            holds(row("a", 4, Expiry::Expired), "a", 4),
            "an expired lease nobody took is renewed"
        );
    }

    #[test]
    fn a_handoff_is_wanted_only_of_a_live_holder_asked_for_it() {
        assert!(wants_handoff(row("a", 4, LIVE), true, "a"));
        assert!(!wants_handoff(row("a", 4, LIVE), false, "a"));
        assert!(!wants_handoff(row("a", 4, LIVE), true, "b"));
        assert!(!wants_handoff(row("a", 4, Expiry::Expired), true, "a"));
        assert!(!wants_handoff(row("a", 4, Expiry::Released), true, "a"));
    }

    #[test]
    fn fences_admit_only_the_current_revision() {
        assert!(check_fence("s", NO_FENCE, None).is_ok());
        assert!(check_fence("s", NO_FENCE, Some(("a", 3))).is_ok());
        assert!(check_fence("s", 3, Some(("a", 3))).is_ok());
        match check_fence("s", 2, Some(("b", 3))) {
            Err(StoreError::Fenced {
                session,
                fence: 2,
                current: Some(3),
                owner: Some(owner),
            }) => assert_eq!((session.as_str(), owner.as_str()), ("s", "b")),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            check_fence("s", 1, None),
            Err(StoreError::Fenced {
                current: None,
                owner: None,
                ..
            })
        ));
    }
}
