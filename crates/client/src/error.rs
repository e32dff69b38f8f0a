//! The client's errors, and reading the API's error body into one.

use dend_protocol::{ErrorBody, ErrorCode, FrameError};

/// Client errors.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Transport failure (reqwest's message, its causes as the `source`
    /// chain: each said once).
    #[error(transparent)]
    Http(#[from] reqwest::Error),
    /// The server answered with an error body.
    #[error("{status}: {code}: {message}")]
    Api {
        /// HTTP status.
        status: u16,
        /// Error code (a code this client does not know is
        /// [`ErrorCode::Other`]).
        code: ErrorCode,
        /// Message.
        message: String,
    },
    /// WebSocket failure (tungstenite's message and causes, each once).
    #[error(transparent)]
    Ws(#[from] Box<tokio_tungstenite::tungstenite::Error>),
    /// A bad frame (its message here, not as a `source`: chained reports
    /// would print it twice).
    #[error("frame: {0}")]
    Frame(FrameError),
    /// Unexpected message or closed connection.
    #[error("protocol: {0}")]
    Protocol(String),
}

impl From<FrameError> for ClientError {
    fn from(e: FrameError) -> Self {
        ClientError::Frame(e)
    }
}

pub(crate) async fn check(r: reqwest::Response) -> Result<reqwest::Response, ClientError> {
    if r.status().is_success() {
        return Ok(r);
    }
    let status = r.status().as_u16();
    let body: ErrorBody = r.json().await.unwrap_or_default();
    Err(ClientError::Api {
        status,
        code: body.code,
        message: body.message,
    })
}
