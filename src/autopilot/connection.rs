//! The link's MAVLink connection, reopened when a stream transport dies.
//!
//! UDP has no connection: a vehicle that goes silent comes back by itself and the link only
//! watches heartbeats. A TCP stream closed by the other end, or a serial device that
//! disappears (a USB adapter unplugged, an autopilot rebooting its USB port), fails every read
//! from then on; such a connection is opened again, with a growing pause between tries, so
//! that the daemon gets its vehicle back without a restart.

use std::sync::Arc;
use std::time::Duration;

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::error::{MessageReadError, MessageWriteError};
use mavlink::{AsyncMavConnection, MavHeader, MavlinkVersion};
use tokio::sync::RwLock;

use super::signing::SigningKey;

type Inner = Arc<mavlink::AsyncConnection<MavMessage>>;

/// A connection that can be reopened.
pub struct Connection {
    url: String,
    signing: Option<(SigningKey, u8)>,
    inner: RwLock<Inner>,
}

/// Longest pause between two tries to reopen.
const MAX_BACKOFF: Duration = Duration::from_secs(2);

impl Connection {
    /// Opens `url` (MAVLink 2 out, any version in, signed with `signing` if given).
    pub async fn open(url: &str, signing: Option<(SigningKey, u8)>) -> std::io::Result<Self> {
        let inner = Self::dial(url, signing.as_ref()).await?;
        Ok(Self {
            url: url.to_string(),
            signing,
            inner: RwLock::new(inner),
        })
    }

    async fn dial(url: &str, signing: Option<&(SigningKey, u8)>) -> std::io::Result<Inner> {
        let mut conn = mavlink::connect_async::<MavMessage>(url).await?;
        conn.set_protocol_version(MavlinkVersion::V2);
        conn.set_allow_recv_any_version(true);
        if let Some((key, link_id)) = signing {
            conn.setup_signing(Some(key.config(*link_id)));
        }
        Ok(Arc::new(conn))
    }

    /// Whether this transport is a stream that must be reopened when it dies.
    pub fn reopens(&self) -> bool {
        self.url.starts_with("tcpout:") || self.url.starts_with("serial:")
    }

    /// Sends one message on the current connection.
    pub async fn send(&self, h: &MavHeader, m: &MavMessage) -> Result<usize, MessageWriteError> {
        let c = self.inner.read().await.clone();
        c.send(h, m).await
    }

    /// Receives one message from the current connection.
    pub async fn recv(&self) -> Result<(MavHeader, MavMessage), MessageReadError> {
        let c = self.inner.read().await.clone();
        c.recv().await
    }

    /// Opens the transport again until it works or `give_up` says so; returns whether it
    /// was reopened.
    pub async fn reopen(&self, give_up: impl Fn() -> bool) -> bool {
        let mut pause = Duration::from_millis(100);
        loop {
            if give_up() {
                return false;
            }
            match Self::dial(&self.url, self.signing.as_ref()).await {
                Ok(c) => {
                    *self.inner.write().await = c;
                    tracing::warn!("link: {} reopened", self.url);
                    return true;
                }
                Err(e) => {
                    tracing::warn!(
                        "link: cannot reopen {}: {e}; again in {:.1} s",
                        self.url,
                        pause.as_secs_f64()
                    );
                    tokio::time::sleep(pause).await;
                    pause = (pause * 2).min(MAX_BACKOFF);
                }
            }
        }
    }
}

/// Whether a read error means the stream is gone (as opposed to one bad frame).
pub fn is_dead_stream(e: &MessageReadError) -> bool {
    use std::io::ErrorKind::*;
    match e {
        MessageReadError::Io(io) => {
            matches!(
                io.kind(),
                UnexpectedEof | BrokenPipe | ConnectionReset | ConnectionAborted | NotConnected
            ) || io.raw_os_error() == Some(5)
        } // EIO: a serial device that went away
        _ => false,
    }
}
