//! A pilot with an RC, for tests of `daemon.engage = "pilot"`: the pilot arms and takes
//! off in the flavour's position mode (PX4 POSCTL, ArduPilot LOITER with the throttle
//! stick centred), and flips the mode switch. The vehicle's mode changes as a switch
//! changes it: no command, no COMMAND_ACK; the companion learns it from the heartbeat.

use super::MockAutopilot;
use infotrack_link::modes::{Flavor, Mode};

impl MockAutopilot {
    /// The pilot arms and climbs to `altitude_m` over where the vehicle stands, holding
    /// position; the RC's throttle stays centred from now on (ArduPilot's LOITER holds
    /// altitude).
    pub fn pilot_take_off(&mut self, altitude_m: f64) {
        self.cfg.rc_throttle_centred = true;
        self.armed = true;
        self.set_mode_internal(Mode::Position);
        let p = self.state.pos_ned_m;
        self.target_ned_m = Some([p[0], p[1], -altitude_m]);
    }

    /// The pilot's arm switch to disarmed (or the firmware's own auto-disarm): refused in
    /// the air, as both firmwares refuse a disarm without the force flag there.
    pub fn pilot_disarm(&mut self) -> Result<(), PilotRefused> {
        if self.state.altitude_m() > 0.2 {
            return Err(PilotRefused("Disarming denied: not landed".into()));
        }
        self.armed = false;
        Ok(())
    }

    /// SET_POSITION_TARGET_LOCAL_NED messages received for this vehicle so far.
    pub fn setpoints_received(&self) -> u64 {
        self.setpoints_received
    }

    /// The pilot's mode switch (or a ground station's mode button). Refused as the firmware
    /// refuses it: PX4 enters OFFBOARD only with a fresh setpoint stream; the firmware's own
    /// modes only. The error is the firmware's message.
    pub fn pilot_switch(&mut self, mode: Mode) -> Result<(), PilotRefused> {
        if mode.custom_mode(self.cfg.flavor).is_none() {
            return Err(PilotRefused(format!(
                "{:?} has no mode {mode:?}",
                self.cfg.flavor
            )));
        }
        if self.cfg.flavor == Flavor::Px4 && mode == Mode::Offboard && !self.setpoints_fresh() {
            return Err(PilotRefused(
                "Offboard rejected: no recent setpoints".into(),
            ));
        }
        self.offboard_lost = false;
        self.set_mode_internal(mode);
        Ok(())
    }
}

/// What the firmware says when it refuses the pilot's switch (its own message).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct PilotRefused(pub String);
