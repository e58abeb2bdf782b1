//! What the mock does with what it is sent: commands, parameter requests and setpoints.

use super::*;

impl MockAutopilot {
    pub(super) fn addressed(&self, sys: u8, comp: u8) -> bool {
        (sys == 0 || sys == self.cfg.system_id) && (comp == 0 || comp == self.cfg.component_id)
    }

    pub(super) fn param_value(&self, i: usize, by_name: bool) -> MavMessage {
        let p = self.params.by_index(i).expect("index checked");
        // ArduPilot answers a read by name with index 65535.
        let index = if by_name && self.cfg.flavor == Flavor::ArduPilot {
            u16::MAX
        } else {
            i as u16
        };
        MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: encode_wire(self.cfg.flavor, p.ty, p.value),
            param_count: self.params.len() as u16,
            param_index: index,
            param_id: p.name.as_str().into(),
            param_type: mav_param_type_of(p.ty),
        })
    }

    /// One COMMAND_LONG, answered as the firmware answers it: the COMMAND_ACK first, then
    /// what the command asked for or the firmware's reason (STATUSTEXT).
    // MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES is deprecated but stock clients send it.
    #[allow(deprecated)]
    pub(super) fn command(&mut self, from: &MavHeader, c: &COMMAND_LONG_DATA) -> Vec<MavMessage> {
        use MavResult::*;
        let mut out = Vec::new();
        let result = match c.command {
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => self.set_message_interval(c, &mut out),
            MavCmd::MAV_CMD_DO_SET_MODE => self.do_set_mode(c, &mut out),
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => self.arm_disarm(c, &mut out),
            MavCmd::MAV_CMD_REQUEST_MESSAGE => match self.requested_message(c.param1 as u32) {
                Some(m) => {
                    out.push(m);
                    MAV_RESULT_ACCEPTED
                }
                None => MAV_RESULT_UNSUPPORTED,
            },
            MavCmd::MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES => {
                out.push(self.autopilot_version());
                MAV_RESULT_ACCEPTED
            }
            // Landing where it is (both: LAND mode), then disarming on the ground (tick).
            MavCmd::MAV_CMD_NAV_LAND if self.armed => {
                self.set_mode_internal(Mode::Land);
                MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_NAV_LAND => MAV_RESULT_FAILED,
            MavCmd::MAV_CMD_DO_CHANGE_ALTITUDE if self.cfg.flavor == Flavor::Px4 => {
                self.offboard_lost = false;
                self.change_altitude_px4(c.param1 as f64, &mut out);
                MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_NAV_TAKEOFF => self.takeoff(c),
            _ => MAV_RESULT_UNSUPPORTED,
        };
        out.insert(0, header_ack(c.command, result, from));
        out
    }

    /// MAV_CMD_SET_MESSAGE_INTERVAL: a stream's rate (below zero: off; zero: the default).
    fn set_message_interval(
        &mut self,
        c: &COMMAND_LONG_DATA,
        out: &mut Vec<MavMessage>,
    ) -> MavResult {
        use MavResult::*;
        if !c.param1.is_finite() {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "SET_MESSAGE_INTERVAL: message id is not a number",
            ));
            return MAV_RESULT_DENIED;
        }
        // PX4 treats an interval that is neither below nor above zero (NaN compares
        // false both ways) as "the default rate"; ArduPilot casts it to an integer, so
        // the mock refuses it there.
        if c.param2.is_nan() && self.cfg.flavor == Flavor::ArduPilot {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "SET_MESSAGE_INTERVAL: interval is not a number",
            ));
            return MAV_RESULT_DENIED;
        }
        let id = c.param1 as u32;
        if c.param2 < 0.0 {
            self.intervals.insert(id, 0.0);
        } else if c.param2 > 0.0 {
            self.intervals.insert(id, c.param2 as f64 / 1e6);
        }
        self.next_due.remove(&id);
        MAV_RESULT_ACCEPTED
    }

    /// MAV_CMD_DO_SET_MODE: the firmware's own modes, refused while a failsafe holds the
    /// mode and (PX4) OFFBOARD without a fresh setpoint stream.
    fn do_set_mode(&mut self, c: &COMMAND_LONG_DATA, out: &mut Vec<MavMessage>) -> MavResult {
        use MavResult::*;
        let mode = Mode::from_do_set_mode(self.cfg.flavor, c.param2, c.param3);
        if c.param1 as u32 & 1 == 0 || matches!(mode, Mode::Other(_)) {
            MAV_RESULT_UNSUPPORTED
        } else if self.mode_locked() {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                "Failsafe: mode change rejected",
            ));
            MAV_RESULT_TEMPORARILY_REJECTED
        } else if mode == Mode::Offboard && !self.setpoints_fresh() {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "Offboard rejected: no recent setpoints",
            ));
            MAV_RESULT_TEMPORARILY_REJECTED
        } else {
            self.offboard_lost = false;
            self.set_mode_internal(mode);
            MAV_RESULT_ACCEPTED
        }
    }

    /// MAV_CMD_COMPONENT_ARM_DISARM. Both firmwares arm on exactly 1 and disarm on exactly
    /// 0; anything else (NaN included) is refused rather than read as one of them. A disarm
    /// in the air needs the force value 21196.
    fn arm_disarm(&mut self, c: &COMMAND_LONG_DATA, out: &mut Vec<MavMessage>) -> MavResult {
        use MavResult::*;
        if c.param1 == 1.0 {
            return self.arm(out);
        }
        if c.param1 != 0.0 {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                &format!("ARM_DISARM: param1 {} is neither 0 nor 1", c.param1),
            ));
            return match self.cfg.flavor {
                Flavor::Px4 => MAV_RESULT_DENIED,
                Flavor::ArduPilot => MAV_RESULT_UNSUPPORTED,
            };
        }
        if self.state.altitude_m() > 0.2 && c.param2 != 21196.0 {
            MAV_RESULT_TEMPORARILY_REJECTED
        } else {
            self.armed = false;
            MAV_RESULT_ACCEPTED
        }
    }

    /// Arming: refused before start-up, without a position estimate, and (PX4) in OFFBOARD
    /// without a fresh setpoint stream.
    fn arm(&mut self, out: &mut Vec<MavMessage>) -> MavResult {
        use MavResult::*;
        if self.armed {
            MAV_RESULT_ACCEPTED
        } else if !self.started_up {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                "Arm: System not initialised",
            ));
            MAV_RESULT_FAILED
        } else if !self.estimator_ready() {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_CRITICAL,
                "PreArm: no position estimate",
            ));
            match self.cfg.flavor {
                Flavor::Px4 => MAV_RESULT_TEMPORARILY_REJECTED,
                Flavor::ArduPilot => MAV_RESULT_FAILED,
            }
        } else if self.cfg.flavor == Flavor::Px4
            && self.mode == Mode::Offboard
            && !self.setpoints_fresh()
        {
            MAV_RESULT_TEMPORARILY_REJECTED
        } else {
            self.armed = true;
            self.armed_at_s = self.now_s;
            self.taking_off = true;
            self.home_ned_m = self.state.pos_ned_m;
            if self.mode == Mode::Offboard {
                self.target_ned_m = self.last_setpoint.map(|(_, p)| p);
            }
            MAV_RESULT_ACCEPTED
        }
    }

    /// MAV_CMD_NAV_TAKEOFF: PX4 takes off in its Takeoff mode, ArduCopter only in GUIDED.
    fn takeoff(&mut self, c: &COMMAND_LONG_DATA) -> MavResult {
        use MavResult::*;
        // PX4 reads a NaN altitude (what MAVSDK's action.takeoff sends) as "the
        // configured take-off altitude", MIS_TAKEOFF_ALT above home.
        let alt = if c.param7.is_nan() && self.cfg.flavor == Flavor::Px4 {
            self.params.get("MIS_TAKEOFF_ALT", 2.5) - self.home_ned_m[2]
        } else {
            c.param7 as f64
        };
        if !self.armed || alt.is_nan() || alt <= 0.0 {
            return MAV_RESULT_FAILED;
        }
        let p = self.state.pos_ned_m;
        match self.cfg.flavor {
            Flavor::ArduPilot if self.mode == Mode::Guided => {
                self.takeoff_alt_m = Some(alt);
                self.target_ned_m = Some([p[0], p[1], -alt]);
                MAV_RESULT_ACCEPTED
            }
            Flavor::ArduPilot => MAV_RESULT_FAILED,
            Flavor::Px4 => {
                self.set_mode_internal(Mode::Takeoff);
                self.target_ned_m = Some([p[0], p[1], -alt]);
                MAV_RESULT_ACCEPTED
            }
        }
    }

    pub(super) fn setpoints_fresh(&self) -> bool {
        let timeout = match self.cfg.flavor {
            Flavor::Px4 => self.params.get("COM_OF_LOSS_T", 1.0),
            Flavor::ArduPilot => f64::INFINITY,
        };
        matches!(self.last_setpoint, Some((t, _)) if self.now_s - t <= timeout)
    }

    /// SET_POSITION_TARGET_LOCAL_NED: checked as the firmware checks it, then followed as
    /// the firmware follows it (PX4: in OFFBOARD; ArduCopter: in GUIDED).
    pub(super) fn setpoint(&mut self, sp: &SET_POSITION_TARGET_LOCAL_NED_DATA) -> Vec<MavMessage> {
        let mut out = Vec::new();
        let Some((target, velocity)) = self.accepted_target(sp, &mut out) else {
            return out;
        };
        match self.cfg.flavor {
            Flavor::Px4 => self.follow_px4(target, velocity, &mut out),
            Flavor::ArduPilot => self.follow_ardupilot(target, velocity, &mut out),
        }
        out
    }

    /// The target's position and velocity (vehicle NED) if the firmware accepts it: a frame
    /// it supports, a position, finite numbers; the yaw is taken when given. A refusal is
    /// said in `out`.
    // BODY_NED and BODY_OFFSET_NED are deprecated in the MAVLink XML but are exactly the frame
    // numbers (8, 9) PX4 and ArduPilot accept.
    #[allow(deprecated)]
    fn accepted_target(
        &mut self,
        sp: &SET_POSITION_TARGET_LOCAL_NED_DATA,
        out: &mut Vec<MavMessage>,
    ) -> Option<([f64; 3], [f64; 3])> {
        let frame_ok = match self.cfg.flavor {
            Flavor::Px4 => matches!(
                sp.coordinate_frame,
                MavFrame::MAV_FRAME_LOCAL_NED | MavFrame::MAV_FRAME_BODY_NED
            ),
            Flavor::ArduPilot => matches!(
                sp.coordinate_frame,
                MavFrame::MAV_FRAME_LOCAL_NED
                    | MavFrame::MAV_FRAME_LOCAL_OFFSET_NED
                    | MavFrame::MAV_FRAME_BODY_NED
                    | MavFrame::MAV_FRAME_BODY_OFFSET_NED
            ),
        };
        let pos_ignored = sp.type_mask.intersects(
            PositionTargetTypemask::POSITION_TARGET_TYPEMASK_X_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Y_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_Z_IGNORE,
        );
        if !frame_ok || pos_ignored {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "position target ignored: unsupported frame or type_mask",
            ));
            return None;
        }
        if ![sp.x, sp.y, sp.z].iter().all(|v| v.is_finite()) {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "position target ignored: non-finite position",
            ));
            return None;
        }
        let target = [sp.x as f64, sp.y as f64, sp.z as f64];
        let vel_ignored = sp.type_mask.intersects(
            PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VX_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VY_IGNORE
                | PositionTargetTypemask::POSITION_TARGET_TYPEMASK_VZ_IGNORE,
        );
        let velocity = if vel_ignored {
            [0.0; 3]
        } else if [sp.vx, sp.vy, sp.vz].iter().all(|v| v.is_finite()) {
            [sp.vx as f64, sp.vy as f64, sp.vz as f64]
        } else {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "position target ignored: non-finite velocity",
            ));
            return None;
        };
        if !sp
            .type_mask
            .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE)
            && sp.yaw.is_finite()
        {
            self.yaw_target_ned_rad = sp.yaw as f64;
        }
        Some((target, velocity))
    }

    /// PX4 follows a setpoint in OFFBOARD, and goes back to OFFBOARD by itself when valid
    /// setpoints resume after it left it for their loss.
    fn follow_px4(&mut self, target: [f64; 3], velocity: [f64; 3], out: &mut Vec<MavMessage>) {
        self.last_setpoint = Some((self.now_s, target));
        if self.mode == Mode::Offboard {
            self.target_ned_m = Some(target);
            self.target_vel_ned_mps = velocity;
        } else if self.offboard_lost {
            // PX4 goes back to OFFBOARD by itself when valid setpoints resume.
            self.offboard_lost = false;
            self.set_mode_internal(Mode::Offboard);
            out.push(self.heartbeat());
        }
    }

    /// ArduCopter follows a setpoint in GUIDED only; one during the climb of a take-off
    /// cancels it.
    fn follow_ardupilot(
        &mut self,
        target: [f64; 3],
        velocity: [f64; 3],
        out: &mut Vec<MavMessage>,
    ) {
        if self.mode != Mode::Guided {
            return; // silently ignored unless GUIDED
        }
        if let Some(alt) = self.takeoff_alt_m {
            if self.state.altitude_m() < 0.95 * alt {
                // A position target during the climb cancels the takeoff.
                self.takeoff_alt_m = None;
                let p = self.state.pos_ned_m;
                self.target_ned_m = Some([p[0], p[1], 0.0]);
                self.events.push(MockEvent::TakeoffCancelled);
                out.push(self.statustext(MavSeverity::MAV_SEVERITY_WARNING, "Takeoff cancelled"));
                return;
            }
            self.takeoff_alt_m = None;
        }
        self.last_setpoint = Some((self.now_s, target));
        self.target_ned_m = Some(target);
        self.target_vel_ned_mps = velocity;
    }
}
