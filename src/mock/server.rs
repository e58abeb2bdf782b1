//! The mock autopilot on a real MAVLink transport (UDP, TCP or serial, as a URL), with
//! fault injection. The behaviour is [`MockAutopilot`]; this only moves messages and keeps
//! the clock.

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{AsyncMavConnection, MavHeader, MavlinkVersion};
use rand::{Rng, SeedableRng};
use tokio::task::JoinHandle;

use super::autopilot::{MockAutopilot, MockConfig, MockEvent};
use crate::rng::CoreRng;

/// Faults the mock injects into its link, both directions.
#[derive(Debug, Clone, Default)]
pub struct Faults {
    /// Share of messages dropped, percent.
    pub loss_percent: f64,
    /// Seed of the loss draws.
    pub seed: u64,
}

/// A running mock autopilot.
pub struct MockHandle {
    autopilot: Arc<Mutex<MockAutopilot>>,
    faults: Arc<Mutex<Faults>>,
    tasks: Vec<JoinHandle<()>>,
}

impl MockHandle {
    /// Runs `f` on the mock's state (for assertions in tests).
    pub fn with<R>(&self, f: impl FnOnce(&mut MockAutopilot) -> R) -> R {
        f(&mut self.autopilot.lock().expect("mock state poisoned"))
    }

    /// Events since the last call (failsafes, cancelled takeoffs).
    pub fn take_events(&self) -> Vec<MockEvent> {
        self.with(|m| m.take_events())
    }

    /// Changes the injected faults.
    pub fn set_faults(&self, f: Faults) {
        *self.faults.lock().expect("faults poisoned") = f;
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
/// `tcpin:...`, `serial:/dev/pts/3:57600`, ...). Physics and telemetry run at 100 Hz.
pub async fn spawn(url: &str, cfg: MockConfig, faults: Faults) -> std::io::Result<MockHandle> {
    let mut conn = mavlink::connect_async::<MavMessage>(url).await?;
    conn.set_protocol_version(MavlinkVersion::V2);
    conn.set_allow_recv_any_version(true);
    let conn = Arc::new(conn);
    let start = Instant::now();
    let autopilot = Arc::new(Mutex::new(MockAutopilot::new(cfg, 0.0)));
    let header = autopilot.lock().expect("fresh").own_header();
    let faults = Arc::new(Mutex::new(faults.clone()));
    let rng = Arc::new(Mutex::new(CoreRng::seed_from_u64(
        faults.lock().expect("fresh").seed,
    )));
    let drop_it = {
        let faults = faults.clone();
        let rng = rng.clone();
        move || {
            let p = faults.lock().expect("faults poisoned").loss_percent;
            p > 0.0 && rng.lock().expect("rng poisoned").gen::<f64>() * 100.0 < p
        }
    };

    let rx_task = {
        let conn = conn.clone();
        let autopilot = autopilot.clone();
        let drop_it = drop_it.clone();
        tokio::spawn(async move {
            loop {
                let (from, msg) = match conn.recv().await {
                    Ok(x) => x,
                    Err(e) => {
                        // A garbled frame or a peer that went away: keep listening.
                        tracing::debug!("mock autopilot: receive error: {e}");
                        tokio::time::sleep(Duration::from_millis(5)).await;
                        continue;
                    }
                };
                if drop_it() {
                    continue;
                }
                let now = start.elapsed().as_secs_f64();
                let replies = autopilot
                    .lock()
                    .expect("mock state poisoned")
                    .handle(now, &from, &msg);
                for r in replies {
                    if !drop_it() {
                        send(&*conn, &header, &r).await;
                    }
                }
            }
        })
    };
    let tick_task = {
        let conn = conn.clone();
        let autopilot = autopilot.clone();
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_millis(10));
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
            loop {
                tick.tick().await;
                let now = start.elapsed().as_secs_f64();
                let out = autopilot.lock().expect("mock state poisoned").tick(now);
                for m in out {
                    if !drop_it() {
                        send(&*conn, &header, &m).await;
                    }
                }
            }
        })
    };
    Ok(MockHandle {
        autopilot,
        faults,
        tasks: vec![rx_task, tick_task],
    })
}

async fn send<C: AsyncMavConnection<MavMessage>>(conn: &C, header: &MavHeader, m: &MavMessage) {
    if let Err(e) = conn.send(header, m).await {
        // No peer yet (udpin before the first packet) or a closed TCP peer.
        tracing::trace!("mock autopilot: send failed: {e}");
    }
}
