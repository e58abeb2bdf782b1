//! The link's MAVLink connection, reopened when a stream transport dies.
//!
//! UDP has no connection: a vehicle that goes silent comes back by itself and the link only
//! watches heartbeats. A TCP stream closed by the other end, or a serial device that
//! disappears (a USB adapter unplugged, an autopilot rebooting its USB port), fails every read
//! from then on; such a connection is opened again, with a growing pause between tries, so
//! that the daemon gets its vehicle back without a restart.
//!
//! Signing is checked here rather than by the mavlink crate: the crate drops a frame whose
//! signature fails without a word, so a wrong key looked like a silent vehicle. This
//! connection receives every frame raw, verifies it with the key itself and counts what it
//! refuses (signed with another key, unsigned while we sign), and notices a vehicle that signs
//! while we do not; [`Connection::signing_diagnosis`] names the mismatch in the link's errors.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::error::{MessageReadError, MessageWriteError};
use mavlink::{
    AsyncMavConnection, MAVLinkMessageRaw, MAVLinkV2MessageRaw, MavHeader, MavlinkVersion,
    SigningData,
};
use tokio::sync::RwLock;

use super::signing::SigningKey;

type Inner = Arc<mavlink::AsyncConnection<MavMessage>>;

/// A connection that can be reopened.
pub struct Connection {
    url: String,
    verifier: Option<SigningData>,
    counts: SigningCounts,
    inner: RwLock<Inner>,
    /// Every message sent and received goes into this telemetry log: one place, whoever
    /// sends.
    tlog: Option<Arc<super::tlog::Tlog>>,
}

/// What the signing check has seen since the link opened.
#[derive(Debug, Default)]
struct SigningCounts {
    /// Signed frames whose signature (or timestamp) failed our key.
    bad_signature: AtomicU64,
    /// Unsigned frames refused because we sign.
    unsigned_refused: AtomicU64,
    /// Signed frames received while we have no key (accepted, unchecked).
    signed_unchecked: AtomicU64,
    /// Frames accepted.
    accepted: AtomicU64,
}

/// The MAVLink 2 incompatibility flag of a signed frame.
const IFLAG_SIGNED: u8 = 0x01;

/// Longest pause between two tries to reopen.
const MAX_BACKOFF: Duration = Duration::from_secs(2);

impl Connection {
    /// Opens `url` (MAVLink 2 out, any version in, signed with `signing` if given).
    pub async fn open(url: &str, signing: Option<(SigningKey, u8)>) -> std::io::Result<Self> {
        let inner = Self::dial(url).await?;
        let verifier = signing
            .as_ref()
            .map(|(key, link_id)| SigningData::from_config(key.config(*link_id)));
        Ok(Self {
            url: url.to_string(),
            verifier,
            counts: SigningCounts::default(),
            inner: RwLock::new(inner),
            tlog: None,
        })
    }

    /// Records every message sent and received from now on in `tlog`.
    pub fn with_tlog(mut self, tlog: Option<Arc<super::tlog::Tlog>>) -> Self {
        self.tlog = tlog;
        self
    }

    /// Opens the transport; signing is done by [`Connection::send`] and [`Connection::recv`].
    async fn dial(url: &str) -> std::io::Result<Inner> {
        let mut conn = mavlink::connect_async::<MavMessage>(url).await?;
        conn.set_protocol_version(MavlinkVersion::V2);
        conn.set_allow_recv_any_version(true);
        Ok(Arc::new(conn))
    }

    /// Whether this transport is a stream that must be reopened when it dies.
    pub fn reopens(&self) -> bool {
        self.url.starts_with("tcpout:") || self.url.starts_with("serial:")
    }

    /// Sends one message on the current connection, signed when we have a key.
    pub async fn send(&self, h: &MavHeader, m: &MavMessage) -> Result<usize, MessageWriteError> {
        if let Some(t) = &self.tlog {
            t.record(h, m);
        }
        let c = self.inner.read().await.clone();
        match &self.verifier {
            None => c.send(h, m).await,
            Some(signer) => {
                let mut raw = MAVLinkV2MessageRaw::new();
                raw.serialize_message_for_signing(*h, m);
                signer.sign_message(&mut raw);
                c.send_raw(&MAVLinkMessageRaw::V2(raw)).await
            }
        }
    }

    /// Receives the next message from the current connection that passes the signing check
    /// (frames refused by it are counted, see [`Connection::signing_diagnosis`]).
    pub async fn recv(&self) -> Result<(MavHeader, MavMessage), MessageReadError> {
        let c = self.inner.read().await.clone();
        loop {
            let raw = c.recv_raw().await?;
            if !self.admits(&raw) {
                continue;
            }
            let header = MavHeader {
                system_id: raw.system_id(),
                component_id: raw.component_id(),
                sequence: raw.sequence(),
            };
            let msg = <MavMessage as mavlink::Message>::parse(
                raw.version(),
                raw.message_id(),
                raw.payload(),
            )
            .map_err(MessageReadError::Parse)?;
            if let Some(t) = &self.tlog {
                t.record(&header, &msg);
            }
            return Ok((header, msg));
        }
    }

    /// Whether `raw` passes the signing check; counts it either way and says the first
    /// refusal in the log.
    fn admits(&self, raw: &MAVLinkMessageRaw) -> bool {
        let signed = match raw {
            MAVLinkMessageRaw::V1(_) => false,
            MAVLinkMessageRaw::V2(m) => m.incompatibility_flags() & IFLAG_SIGNED != 0,
        };
        let c = &self.counts;
        let (counter, admitted) = match (&self.verifier, raw) {
            (None, _) if signed => (&c.signed_unchecked, true),
            (None, _) => (&c.accepted, true),
            (Some(_), _) if !signed => (&c.unsigned_refused, false),
            (Some(v), MAVLinkMessageRaw::V2(m)) if v.verify_signature(m) => (&c.accepted, true),
            (Some(_), _) => (&c.bad_signature, false),
        };
        if counter.fetch_add(1, Ordering::Relaxed) == 0 && !admitted {
            tracing::warn!("link: {}", self.signing_diagnosis().unwrap_or_default());
        }
        admitted
    }

    /// A sentence naming a signing mismatch seen on this link, if any: frames signed with
    /// another key, unsigned frames while we sign, or a vehicle that signs while we do not
    /// (it then refuses our unsigned commands).
    pub fn signing_diagnosis(&self) -> Option<String> {
        let c = &self.counts;
        let bad = c.bad_signature.load(Ordering::Relaxed);
        let unsigned = c.unsigned_refused.load(Ordering::Relaxed);
        let peer_signs = c.signed_unchecked.load(Ordering::Relaxed);
        if bad > 0 {
            return Some(format!(
                "signing mismatch: {bad} frame(s) from the vehicle were signed with a different \
                 key than daemon.signing_key (or replayed) and were refused; give infotrack the \
                 vehicle's key"
            ));
        }
        if unsigned > 0 {
            return Some(format!(
                "signing mismatch: {unsigned} unsigned frame(s) were refused because \
                 daemon.signing_key is set and the vehicle does not sign; set up signing on the \
                 vehicle with the same key, or remove daemon.signing_key"
            ));
        }
        if peer_signs > 0 {
            return Some(format!(
                "signing mismatch: the vehicle signs its messages ({peer_signs} signed frame(s) \
                 seen) and infotrack has no daemon.signing_key, so the vehicle may refuse our \
                 unsigned commands; give infotrack the vehicle's key"
            ));
        }
        None
    }

    /// Opens the transport again until it works or `give_up` says so; returns whether it
    /// was reopened.
    pub async fn reopen(&self, give_up: impl Fn() -> bool) -> bool {
        let mut pause = Duration::from_millis(100);
        loop {
            if give_up() {
                return false;
            }
            match Self::dial(&self.url).await {
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
