//! Session authentication, in one place: the bearer token of a request
//! and its check against a session.
//!
//! A session's access token is 256 random bits (hex), returned once at
//! creation; only its SHA-256 is kept, compared in constant time. HTTP
//! requests carry it as `Authorization: Bearer <token>`; a WebSocket
//! upgrade may carry it there, as `?token=`, or in its first `auth`
//! message.

use axum::http::{header, HeaderMap};
use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

use crate::error::ApiError;
use crate::session::SessionHandle;

/// A new random id (of a mesh or a session): 128 bits, hex.
pub(crate) fn new_id() -> String {
    let b: [u8; 16] = rand::random();
    hex::encode(b)
}

/// SHA-256 of a token.
pub(crate) fn token_hash(token: &str) -> [u8; 32] {
    Sha256::digest(token.as_bytes()).into()
}

/// Checks `token` against a live session in constant time
/// ([`check_token_hash`]).
pub(crate) fn check_token(s: &SessionHandle, token: Option<&str>) -> Result<(), ApiError> {
    check_token_hash(s.token_sha256(), token)
}

/// Checks `token` against a session's token hash in constant time:
/// `MissingToken` without one, `WrongToken` when it does not match.
pub(crate) fn check_token_hash(sha256: &[u8; 32], token: Option<&str>) -> Result<(), ApiError> {
    let token = token.ok_or(ApiError::MissingToken)?;
    if bool::from(token_hash(token).ct_eq(sha256)) {
        Ok(())
    } else {
        Err(ApiError::WrongToken)
    }
}

/// The token of an `Authorization: Bearer <token>` header, without the
/// whitespace around it; `None` without the header or with another
/// scheme. The scheme is matched case-insensitively (RFC 9110 §11.1).
pub(crate) fn bearer(headers: &HeaderMap) -> Option<&str> {
    let value = headers.get(header::AUTHORIZATION)?.to_str().ok()?;
    let (scheme, token) = value.trim_start().split_once(' ')?;
    scheme
        .eq_ignore_ascii_case("bearer")
        .then_some(token.trim())
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn headers(value: &str) -> HeaderMap {
        let mut h = HeaderMap::new();
        let _ = h.insert(header::AUTHORIZATION, HeaderValue::from_str(value).unwrap());
        h
    }

    /// The HTTP routes and the WebSocket upgrade read the same token from
    /// every spelling of the header (one of them used not to trim it).
    #[test]
    fn bearer_reads_the_token_from_every_spelling() {
        for value in [
            "Bearer abc123",
            "Bearer abc123 ",
            "Bearer   abc123\t",
            "bearer abc123",
            "BEARER abc123",
            " Bearer abc123",
        ] {
            assert_eq!(bearer(&headers(value)), Some("abc123"), "{value:?}");
        }
    }

    #[test]
    fn bearer_is_none_without_the_header_or_with_another_scheme() {
        assert_eq!(bearer(&HeaderMap::new()), None);
        for value in [
            "Basic abc123",
            "Bearerabc123",
            "Bearer",
            "abc123",
            "Token abc123",
        ] {
            assert_eq!(bearer(&headers(value)), None, "{value:?}");
        }
    }

    /// An empty token is read as given (and then refused as wrong, as
    /// before), not taken for a missing header.
    #[test]
    fn an_empty_bearer_token_is_empty_not_missing() {
        assert_eq!(bearer(&headers("Bearer ")), Some(""));
        assert_eq!(bearer(&headers("Bearer   ")), Some(""));
    }
}
