//! A WebSocket connection to a session: sending drags and acks, reading
//! frames (decoded, flow-control acknowledged) and events.

use futures_util::{SinkExt, StreamExt};
use tokio_tungstenite::tungstenite::Message;

use dend_protocol::ws::{ClientMsg, DeltaJson, HandleRef, ServerMsg};
use dend_protocol::{DecodedFrame, FrameDecoder, FrameHeader};

use crate::error::ClientError;

/// A message from the server.
// an event holds the whole session snapshot (`state`); boxing it would buy
// nothing for a message handed once to its reader
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum WsEvent {
    /// A pose frame.
    Frame(FrameHeader, Vec<[f32; 3]>),
    /// A JSON event.
    Event(ServerMsg),
    /// The server closed (code).
    Closed(Option<u16>),
}

/// A WebSocket connection to a session.
pub struct WsClient {
    ws: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
    /// Whether the connection declared a flow-control window (frames are
    /// acknowledged).
    flow: bool,
    /// The revision of the last frame handed to the caller, acknowledged
    /// when the caller asks for the next message (it has taken the frame).
    to_ack: Option<u64>,
    /// Bytes of the binary frames received.
    bytes: u64,
    /// Holds the last `delta` frame, which the next one's changes apply to.
    decoder: FrameDecoder,
}

impl std::fmt::Debug for WsClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WsClient")
            .field("flow", &self.flow)
            .field("bytes", &self.bytes)
            .finish_non_exhaustive()
    }
}

impl WsClient {
    /// Connects to the session's WebSocket at `url`; `flow`: the
    /// connection declared a flow-control window (frames are acknowledged).
    pub(crate) async fn open(url: String, flow: bool) -> Result<WsClient, ClientError> {
        // TCP_NODELAY: an ack and the next drag go out at once instead of
        // waiting for the server's delayed ACK (Nagle's algorithm)
        let (ws, _) = tokio_tungstenite::connect_async_with_config(url, None, true)
            .await
            .map_err(Box::new)?;
        Ok(WsClient {
            ws,
            flow,
            to_ack: None,
            bytes: 0,
            decoder: FrameDecoder::new(),
        })
    }

    /// Sends a message.
    pub async fn send(&mut self, m: &ClientMsg) -> Result<(), ClientError> {
        let text = serde_json::to_string(m).map_err(|e| ClientError::Protocol(e.to_string()))?;
        self.ws
            .send(Message::Text(text.into()))
            .await
            .map_err(Box::new)?;
        Ok(())
    }

    /// Sends a drag delta (translation; rotation as quaternion `[x,y,z,w]`).
    pub async fn drag(
        &mut self,
        handle: usize,
        translate: [f64; 3],
        quaternion: Option<[f64; 4]>,
        seq: u64,
    ) -> Result<(), ClientError> {
        self.send(&ClientMsg::Drag {
            handle: HandleRef::Index(handle),
            delta: DeltaJson::new(translate, quaternion),
            seq,
        })
        .await
    }

    /// Bytes of pose frames received so far.
    pub fn frame_bytes(&self) -> u64 {
        self.bytes
    }

    /// Acknowledges the last frame handed out, if not yet done (also done
    /// by [`WsClient::next`]: call it when a frame is taken before asking
    /// for the next message).
    pub async fn ack(&mut self) -> Result<(), ClientError> {
        // cleared once sent: a call cancelled mid-send acks again later
        if let Some(revision) = self.to_ack {
            self.send(&ClientMsg::Ack { revision }).await?;
            self.to_ack = None;
        }
        Ok(())
    }

    /// The next frame (with its box and encoding) or event. Asking for it
    /// acknowledges the frame handed out before.
    pub async fn next_full(&mut self) -> Result<WsFull, ClientError> {
        self.ack().await?;
        loop {
            match self.ws.next().await {
                None => return Ok(WsFull::Closed(None)),
                Some(Err(e)) => return Err(Box::new(e).into()),
                Some(Ok(Message::Binary(b))) => {
                    self.bytes += b.len() as u64;
                    let f = self.decoder.decode(&b)?;
                    if self.flow {
                        self.to_ack = Some(f.header.revision);
                    }
                    return Ok(WsFull::Frame(f));
                }
                Some(Ok(Message::Text(t))) => {
                    return serde_json::from_str(&t)
                        .map(WsFull::Event)
                        .map_err(|e| ClientError::Protocol(format!("{e}: {t}")));
                }
                Some(Ok(Message::Close(c))) => return Ok(WsFull::Closed(c.map(|c| c.code.into()))),
                Some(Ok(_)) => continue,
            }
        }
    }

    /// The next frame or event. Asking for it acknowledges the frame
    /// handed out before.
    pub async fn next(&mut self) -> Result<WsEvent, ClientError> {
        Ok(match self.next_full().await? {
            WsFull::Frame(f) => WsEvent::Frame(f.header, f.positions),
            WsFull::Event(e) => WsEvent::Event(e),
            WsFull::Closed(c) => WsEvent::Closed(c),
        })
    }

    /// Skips to the next event of kind `kind` (its `type`: `state`,
    /// `error`, `ready`, …; frames and other events dropped).
    pub async fn event(&mut self, kind: &str) -> Result<ServerMsg, ClientError> {
        loop {
            match self.next().await? {
                WsEvent::Event(m) if m.kind() == kind => return Ok(m),
                WsEvent::Closed(c) => {
                    return Err(ClientError::Protocol(format!(
                        "closed ({c:?}) before `{kind}`"
                    )))
                }
                _ => {}
            }
        }
    }

    /// Reads until a frame acknowledges `seq` (and is converged, if asked).
    pub async fn frame_acking(
        &mut self,
        seq: u64,
        converged: bool,
    ) -> Result<(FrameHeader, Vec<[f32; 3]>), ClientError> {
        loop {
            match self.next().await? {
                WsEvent::Frame(h, v) if h.ack_seq >= seq && (h.converged || !converged) => {
                    return Ok((h, v))
                }
                WsEvent::Event(e @ ServerMsg::Error { .. }) => {
                    return Err(ClientError::Protocol(format!("error event: {e:?}")));
                }
                WsEvent::Closed(c) => return Err(ClientError::Protocol(format!("closed ({c:?})"))),
                _ => {}
            }
        }
    }

    /// Closes the connection.
    pub async fn close(mut self) -> Result<(), ClientError> {
        self.ws.close(None).await.map_err(Box::new)?;
        Ok(())
    }
}

/// A message from the server, frames with their box and encoding.
// as `WsEvent`
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum WsFull {
    /// A pose frame.
    Frame(DecodedFrame),
    /// A JSON event.
    Event(ServerMsg),
    /// The server closed (code).
    Closed(Option<u16>),
}
