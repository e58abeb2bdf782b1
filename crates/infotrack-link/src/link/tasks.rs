//! The link's background tasks: the reader, our heartbeat, the watchdog and the setpoint
//! streamer.

use super::*;

/// The reader: every message into the tlog and the vehicle state; a dead stream reopened.
pub(super) fn spawn_reader(
    conn: Arc<Connection>,
    state: SharedState,
    events: broadcast::Sender<LinkEvent>,
    ids: Ids,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            match conn.recv().await {
                Ok((h, m)) => on_message(&state, &events, ids, &h, &m),
                Err(e) if conn.reopens() && is_dead_stream(&e) => {
                    tracing::error!("link: {e}: the connection is gone; reopening");
                    conn.reopen(|| false).await;
                }
                Err(e) => {
                    tracing::debug!("link: receive error: {e}");
                    tokio::time::sleep(Duration::from_millis(5)).await;
                }
            }
        }
    })
}

/// Our heartbeat, once a second (unless paused by a test of the vehicle's failsafe).
pub(super) fn spawn_heartbeat(
    conn: Arc<Connection>,
    paused: Arc<AtomicBool>,
    header: MavHeader,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut t = tokio::time::interval(Duration::from_secs(1));
        loop {
            t.tick().await;
            if paused.load(Ordering::Relaxed) {
                continue;
            }
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            });
            let _ = conn.send(&header, &hb).await;
        }
    })
}

/// Declares the vehicle lost when its heartbeat is older than `timeout`.
pub(super) fn spawn_watchdog(
    state: SharedState,
    events: broadcast::Sender<LinkEvent>,
    timeout: Duration,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut t = tokio::time::interval(Duration::from_millis(100));
        loop {
            t.tick().await;
            let mut s = state.lock();
            let stale = s.last_heartbeat.is_some_and(|h| h.elapsed() > timeout);
            if stale && !s.lost {
                s.lost = true;
                tracing::warn!("vehicle lost: no heartbeat for {timeout:?}");
                let _ = events.send(LinkEvent::VehicleLost);
            }
        }
    })
}

/// The setpoint stream: the current target every `period`, unless paused.
pub(super) fn spawn_streamer(
    conn: Arc<Connection>,
    streamer: Arc<Streamer>,
    state: SharedState,
    header: MavHeader,
    period: Duration,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut t = tokio::time::interval(period);
        t.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let start = Instant::now();
        loop {
            t.tick().await;
            if streamer.paused.load(Ordering::Relaxed) {
                continue;
            }
            let Some(target_sp) = *streamer.target_ned.lock() else {
                continue;
            };
            let (p, v) = target_sp.at(Instant::now(), streamer.geofence_enu.as_ref());
            let p = world_to_vehicle_ned(streamer.placement().as_ref(), p);
            // No vehicle locked yet: a setpoint has nobody to go to.
            let Some(target) = state.lock().address else {
                continue;
            };
            let m = position_target(
                target,
                p,
                v,
                target_sp.yaw_ned,
                start.elapsed().as_millis() as u32,
            );
            if conn.send(&header, &m).await.is_ok() {
                streamer.sent.lock().note(Instant::now());
            }
        }
    })
}
