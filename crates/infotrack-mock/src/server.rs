//! The mock autopilot on a real MAVLink transport (UDP, TCP or serial, as a URL), with
//! fault injection and optional MAVLink 2 signing. The behaviour is [`MockAutopilot`]; this
//! only moves messages, keeps the clock and misbehaves on request.

use std::sync::Arc;

use parking_lot::Mutex;
use std::time::Duration;
use tokio::time::Instant;

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{AsyncMavConnection, MavHeader, MavlinkVersion};
use rand::{Rng, SeedableRng};
use tokio::task::JoinHandle;

use super::autopilot::{MockAutopilot, MockConfig, MockEvent};
use infotrack_core::rng::CoreRng;
use infotrack_link::signing::SigningKey;

/// How long a message picked for reordering is held back, so that the next ones overtake
/// it (several telemetry periods at the default rates).
const REORDER_HOLD: Duration = Duration::from_millis(40);

/// Faults the mock injects into its link, both directions, each message drawn on its own.
#[derive(Debug, Clone, Default)]
pub struct Faults {
    /// Share of messages dropped, percent.
    pub loss_percent: f64,
    /// One-way latency added to every message.
    pub delay: Duration,
    /// Share of messages delivered twice, percent.
    pub duplicate_percent: f64,
    /// Share of messages held back so that later ones overtake them, percent.
    pub reorder_percent: f64,
    /// Seed of the fault draws.
    pub seed: u64,
}

/// Transport-level options of a mock.
#[derive(Debug, Clone, Default)]
pub struct ServerOptions {
    /// Injected faults.
    pub faults: Faults,
    /// When set, the mock signs what it sends and drops every frame that is not signed with
    /// this key (as ArduPilot does once signing is set up): unsigned commands are refused.
    pub signing_key: Option<SigningKey>,
}

/// Link-level state shared by the mock's tasks.
struct Wire {
    faults: Faults,
    rng: CoreRng,
    /// No traffic either way until then (a cut cable, a radio out of range).
    cut_until: Option<Instant>,
    /// Rebooting: silent, deaf, until then.
    down_until: Option<Instant>,
    /// Frames dropped because they were not signed with the key.
    rejected_unsigned: u64,
}

impl Wire {
    fn silent(&self, now: Instant) -> bool {
        self.cut_until.is_some_and(|t| now < t) || self.down_until.is_some_and(|t| now < t)
    }

    /// When each copy of one message is delivered, from now; empty: dropped.
    fn plan(&mut self, now: Instant) -> Vec<Duration> {
        if self.silent(now) {
            return Vec::new();
        }
        let f = &self.faults;
        let hit = |rng: &mut CoreRng, p: f64| p > 0.0 && rng.gen::<f64>() * 100.0 < p;
        let (loss, dup, reorder) = (f.loss_percent, f.duplicate_percent, f.reorder_percent);
        if hit(&mut self.rng, loss) {
            return Vec::new();
        }
        let mut delay = f.delay;
        if hit(&mut self.rng, reorder) {
            delay += REORDER_HOLD;
        }
        if hit(&mut self.rng, dup) {
            vec![delay, delay]
        } else {
            vec![delay]
        }
    }
}

type Conn = Arc<mavlink::AsyncConnection<MavMessage>>;

/// A running mock autopilot.
pub struct MockHandle {
    autopilot: Arc<Mutex<MockAutopilot>>,
    wire: Arc<Mutex<Wire>>,
    start: Instant,
    tasks: Vec<JoinHandle<()>>,
}

impl MockHandle {
    /// Runs `f` on the mock's state (for assertions in tests).
    pub fn with<R>(&self, f: impl FnOnce(&mut MockAutopilot) -> R) -> R {
        f(&mut self.autopilot.lock())
    }

    /// Events since the last call (failsafes, cancelled takeoffs).
    pub fn take_events(&self) -> Vec<MockEvent> {
        self.with(|m| m.take_events())
    }

    /// Changes the injected faults (the draws go on from the same generator).
    pub fn set_faults(&self, f: Faults) {
        self.wire.lock().faults = f;
    }

    /// Cuts the link both ways for `d` from now; the vehicle goes on flying and its
    /// failsafes see the silence.
    pub fn cut_link(&self, d: Duration) {
        self.wire.lock().cut_until = Some(Instant::now() + d);
    }

    /// A power cycle: silent for `boot_time`, then a fresh vehicle (disarmed, on the ground
    /// at home, its boot clock restarted) that kept its parameters.
    pub fn reboot(&self, boot_time: Duration) {
        let now = Instant::now();
        self.wire.lock().down_until = Some(now + boot_time);
        let boot_s = (now + boot_time - self.start).as_secs_f64();
        self.with(|m| m.reboot(boot_s));
    }

    /// Frames the mock dropped because they were not signed with its key.
    pub fn rejected_unsigned(&self) -> u64 {
        self.wire.lock().rejected_unsigned
    }

    /// Stops the mock.
    pub fn stop(self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

impl Drop for MockHandle {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
    }
}

/// Starts a mock autopilot listening or connecting at `url` (`udpin:127.0.0.1:14550`,
/// `tcpin:...`, `serial:/dev/pts/3:57600`, ...) with faults and no signing. Physics and
/// telemetry run at 100 Hz.
pub async fn spawn(url: &str, cfg: MockConfig, faults: Faults) -> std::io::Result<MockHandle> {
    spawn_with(
        url,
        cfg,
        ServerOptions {
            faults,
            signing_key: None,
        },
    )
    .await
}

/// Starts a mock autopilot at `url` with the given transport options.
pub async fn spawn_with(
    url: &str,
    cfg: MockConfig,
    opts: ServerOptions,
) -> std::io::Result<MockHandle> {
    let mut conn = mavlink::connect_async::<MavMessage>(url).await?;
    conn.set_protocol_version(MavlinkVersion::V2);
    conn.set_allow_recv_any_version(true);
    let signing = opts.signing_key.is_some();
    if let Some(key) = &opts.signing_key {
        // Unsigned frames are let through the crate so that the mock can count what it
        // refuses; badly signed ones the crate drops itself.
        conn.setup_signing(Some(mavlink::SigningConfig::new(key.0, 0, true, true)));
    }
    let conn: Conn = Arc::new(conn);
    let start = Instant::now();
    let autopilot = Arc::new(Mutex::new(MockAutopilot::new(cfg, 0.0)));
    let header = autopilot.lock().own_header();
    let wire = Arc::new(Mutex::new(Wire {
        rng: CoreRng::seed_from_u64(opts.faults.seed),
        faults: opts.faults,
        cut_until: None,
        down_until: None,
        rejected_unsigned: 0,
    }));

    let shared = Shared {
        conn,
        autopilot: autopilot.clone(),
        wire: wire.clone(),
        start,
        header,
    };
    let rx_task = tokio::spawn(receive_loop(shared.clone(), signing));
    let tick_task = tokio::spawn(tick_loop(shared));
    let tasks = vec![rx_task, tick_task];
    Ok(MockHandle {
        autopilot,
        wire,
        start,
        tasks,
    })
}

/// What the mock's two loops share: the transport, the autopilot, the fault shell, when
/// it started and the header it sends with.
#[derive(Clone)]
struct Shared {
    conn: Conn,
    autopilot: Arc<Mutex<MockAutopilot>>,
    wire: Arc<Mutex<Wire>>,
    start: Instant,
    header: MavHeader,
}

/// Receives for ever: each message reaches the autopilot when the fault shell lets it
/// (dropped, delayed or duplicated), and its replies go out through the shell.
async fn receive_loop(s: Shared, signing: bool) {
    loop {
        let (from, msg) = match receive(&s.conn, signing).await {
            Ok(Some(x)) => x,
            Ok(None) => {
                s.wire.lock().rejected_unsigned += 1;
                continue;
            }
            Err(e) => {
                // A garbled frame or a peer that went away: keep listening.
                tracing::debug!("mock autopilot: receive error: {e}");
                tokio::time::sleep(Duration::from_millis(5)).await;
                continue;
            }
        };
        let plan = s.wire.lock().plan(Instant::now());
        for delay in plan {
            let (s, msg) = (s.clone(), msg.clone());
            let deliver = async move {
                let now = s.start.elapsed().as_secs_f64();
                let replies = s.autopilot.lock().handle(now, &from, &msg);
                for r in replies {
                    transmit(&s.conn, &s.wire, s.header, r).await;
                }
            };
            if delay.is_zero() {
                deliver.await;
            } else {
                tokio::spawn(async move {
                    tokio::time::sleep(delay).await;
                    deliver.await;
                });
            }
        }
    }
}

/// Ticks the autopilot every 10 ms and sends what it streams.
async fn tick_loop(s: Shared) {
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        tick.tick().await;
        let now = s.start.elapsed().as_secs_f64();
        let out = s.autopilot.lock().tick(now);
        for m in out {
            transmit(&s.conn, &s.wire, s.header, m).await;
        }
    }
}

/// The next message; `None` for a frame refused because signing is on and it is unsigned.
async fn receive(
    conn: &Conn,
    signing: bool,
) -> Result<Option<(MavHeader, MavMessage)>, mavlink::error::MessageReadError> {
    if !signing {
        return conn.recv().await.map(Some);
    }
    let raw = conn.recv_raw().await?;
    let signed = match &raw {
        mavlink::MAVLinkMessageRaw::V1(_) => false,
        mavlink::MAVLinkMessageRaw::V2(m) => m.incompatibility_flags() & 0x01 != 0,
    };
    if !signed {
        return Ok(None);
    }
    let header = MavHeader {
        system_id: raw.system_id(),
        component_id: raw.component_id(),
        sequence: raw.sequence(),
    };
    let msg =
        <MavMessage as mavlink::Message>::parse(raw.version(), raw.message_id(), raw.payload())
            .map_err(mavlink::error::MessageReadError::Parse)?;
    Ok(Some((header, msg)))
}

/// Sends `m` through the fault plan.
async fn transmit(conn: &Conn, wire: &Arc<Mutex<Wire>>, header: MavHeader, m: MavMessage) {
    let plan = wire.lock().plan(Instant::now());
    for delay in plan {
        if delay.is_zero() {
            send(&**conn, &header, &m).await;
        } else {
            let (conn, m) = (conn.clone(), m.clone());
            tokio::spawn(async move {
                tokio::time::sleep(delay).await;
                send(&*conn, &header, &m).await;
            });
        }
    }
}

async fn send<C: AsyncMavConnection<MavMessage>>(conn: &C, header: &MavHeader, m: &MavMessage) {
    if let Err(e) = conn.send(header, m).await {
        // No peer yet (udpin before the first packet) or a closed TCP peer.
        tracing::trace!("mock autopilot: send failed: {e}");
    }
}
