//! The setpoint being streamed, its frames and the SET_POSITION_TARGET_LOCAL_NED it becomes.

use super::*;

pub(super) struct Streamer {
    /// In the world frame's NED axes (converted to the vehicle's frame when sent).
    pub(super) target_ned: Mutex<Option<StreamedTarget>>,
    pub(super) paused: AtomicBool,
    /// Where a moving setpoint stops (world ENU).
    pub(super) geofence_enu: Option<BoundsEnu>,
    /// Where the vehicle's local frame lies in the world's; None: they are the same frame.
    pub(super) placement: Mutex<Option<WorldPlacement>>,
    /// How the stream went: setpoints sent, and when the first and the last went.
    pub(super) sent: Mutex<SetpointStats>,
}

/// How the setpoint stream went: what a companion's CPU budget is judged by (an autopilot
/// leaves offboard or guided control when setpoints stop coming).
#[derive(Debug, Clone, Copy, Default)]
pub struct SetpointStats {
    /// Setpoints sent.
    pub sent: u64,
    /// When the first and the last were sent.
    pub span: Option<(Instant, Instant)>,
}

impl SetpointStats {
    /// Setpoints per second between the first and the last (`None` before two).
    pub fn rate_hz(&self) -> Option<f64> {
        let (first, last) = self.span?;
        let s = (last - first).as_secs_f64();
        (self.sent >= 2 && s > 0.0).then(|| (self.sent - 1) as f64 / s)
    }

    pub(super) fn note(&mut self, now: Instant) {
        self.sent += 1;
        self.span = Some((self.span.map_or(now, |(first, _)| first), now));
    }
}

impl Streamer {
    pub(super) fn placement(&self) -> Option<WorldPlacement> {
        *self.placement.lock()
    }
}

/// A position in the world frame's NED axes, in the vehicle's local NED frame (the same
/// without a placement). Heights are not converted (see [`WorldPlacement`]).
pub(super) fn world_to_vehicle_ned(
    placement: Option<&WorldPlacement>,
    p: PositionNed,
) -> PositionNed {
    match placement {
        None => p,
        Some(pl) => horizontally(p, |en| pl.world_to_vehicle_en_m(en)),
    }
}

/// The inverse of [`world_to_vehicle_ned`]: the vehicle's local NED in the world's axes.
pub(super) fn vehicle_to_world_ned(
    placement: Option<&WorldPlacement>,
    p: PositionNed,
) -> PositionNed {
    match placement {
        None => p,
        Some(pl) => horizontally(p, |en| pl.vehicle_to_world_en_m(en)),
    }
}

/// `p` with its (east, north) mapped by `f` and its height kept.
fn horizontally(p: PositionNed, f: impl Fn([f64; 2]) -> [f64; 2]) -> PositionNed {
    let [e, n] = f([p.y_east_m, p.x_north_m]);
    PositionNed {
        x_north_m: n,
        y_east_m: e,
        z_down_m: p.z_down_m,
    }
}

/// The setpoint being streamed: a point moving at a constant velocity from `since` on.
#[derive(Debug, Clone, Copy)]
pub(super) struct StreamedTarget {
    pub(super) position_ned: PositionNed,
    /// m/s, local NED.
    pub(super) velocity_ned: [f64; 3],
    pub(super) yaw_ned: f32,
    pub(super) since: Instant,
}

impl StreamedTarget {
    /// Position and velocity at `now`; a setpoint that would leave the geofence stops at
    /// its edge with no velocity.
    pub(super) fn at(&self, now: Instant, fence: Option<&BoundsEnu>) -> (PositionNed, [f64; 3]) {
        let dt = now.saturating_duration_since(self.since).as_secs_f64();
        let v = self.velocity_ned;
        let p = PositionNed {
            x_north_m: self.position_ned.x_north_m + v[0] * dt,
            y_east_m: self.position_ned.y_east_m + v[1] * dt,
            z_down_m: self.position_ned.z_down_m + v[2] * dt,
        };
        match fence {
            Some(f) if !f.contains(&p.to_enu().xy()) => {
                let e = p.to_enu();
                let c = f.clamp(&e.xy());
                (PositionEnu::from_xy(&c, e.z_up_m).to_ned(), [0.0; 3])
            }
            _ => (p, v),
        }
    }
}

/// A local NED target: position and yaw, plus the velocity as feed-forward when it is not
/// zero. Masks: 2552 (position + yaw) and 2496 (position + velocity + yaw), which PX4's
/// offboard mode and ArduPilot's GUIDED both accept (3576 and 3520 with yaw ignored).
pub(super) fn position_target(
    target: (u8, u8),
    p: PositionNed,
    v_ned: [f64; 3],
    yaw_ned: f32,
    time_boot_ms: u32,
) -> MavMessage {
    let mut mask = PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AX_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AY_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_AZ_IGNORE
        | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE;
    if v_ned == [0.0; 3] {
        mask |= PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
            | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE;
    }
    MavMessage::SET_POSITION_TARGET_LOCAL_NED(SET_POSITION_TARGET_LOCAL_NED_DATA {
        time_boot_ms,
        x: p.x_north_m as f32,
        y: p.y_east_m as f32,
        z: p.z_down_m as f32,
        vx: v_ned[0] as f32,
        vy: v_ned[1] as f32,
        vz: v_ned[2] as f32,
        yaw: yaw_ned,
        type_mask: mask,
        target_system: target.0,
        target_component: target.1,
        coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
        ..Default::default()
    })
}
