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

    // Long because it is one dispatch over the COMMAND_LONG ids the firmware answers, one
    // short arm each, kept together so the table of supported commands reads at a glance.
    // MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES is deprecated but stock clients send it.
    #[allow(deprecated)]
    pub(super) fn command(&mut self, from: &MavHeader, c: &COMMAND_LONG_DATA) -> Vec<MavMessage> {
        use MavResult::*;
        let mut out = Vec::new();
        let result = match c.command {
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL if !c.param1.is_finite() => {
                out.push(self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "SET_MESSAGE_INTERVAL: message id is not a number",
                ));
                MAV_RESULT_DENIED
            }
            // PX4 treats an interval that is neither below nor above zero (NaN compares
            // false both ways) as "the default rate"; ArduPilot casts it to an integer, so
            // the mock refuses it there.
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL
                if c.param2.is_nan() && self.cfg.flavor == Flavor::ArduPilot =>
            {
                out.push(self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    "SET_MESSAGE_INTERVAL: interval is not a number",
                ));
                MAV_RESULT_DENIED
            }
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                let id = c.param1 as u32;
                if c.param2 < 0.0 {
                    self.intervals.insert(id, 0.0);
                } else if c.param2 > 0.0 {
                    self.intervals.insert(id, c.param2 as f64 / 1e6);
                }
                self.next_due.remove(&id);
                MAV_RESULT_ACCEPTED
            }
            MavCmd::MAV_CMD_DO_SET_MODE => {
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
            // Both firmwares arm on exactly 1 and disarm on exactly 0; anything else (NaN
            // included) is refused rather than read as one of them.
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM if c.param1 != 0.0 && c.param1 != 1.0 => {
                out.push(self.statustext(
                    MavSeverity::MAV_SEVERITY_WARNING,
                    &format!("ARM_DISARM: param1 {} is neither 0 nor 1", c.param1),
                ));
                match self.cfg.flavor {
                    Flavor::Px4 => MAV_RESULT_DENIED,
                    Flavor::ArduPilot => MAV_RESULT_UNSUPPORTED,
                }
            }
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
                if c.param1 == 1.0 {
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
                } else if self.state.altitude_m() > 0.2 && c.param2 != 21196.0 {
                    MAV_RESULT_TEMPORARILY_REJECTED
                } else {
                    self.armed = false;
                    MAV_RESULT_ACCEPTED
                }
            }
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
            MavCmd::MAV_CMD_NAV_TAKEOFF => {
                // PX4 reads a NaN altitude (what MAVSDK's action.takeoff sends) as "the
                // configured take-off altitude", MIS_TAKEOFF_ALT above home.
                let alt = if c.param7.is_nan() && self.cfg.flavor == Flavor::Px4 {
                    self.params.get("MIS_TAKEOFF_ALT", 2.5) - self.home_ned_m[2]
                } else {
                    c.param7 as f64
                };
                if !self.armed || alt.is_nan() || alt <= 0.0 {
                    MAV_RESULT_FAILED
                } else {
                    match self.cfg.flavor {
                        Flavor::ArduPilot if self.mode == Mode::Guided => {
                            self.takeoff_alt_m = Some(alt);
                            let p = self.state.pos_ned_m;
                            self.target_ned_m = Some([p[0], p[1], -alt]);
                            MAV_RESULT_ACCEPTED
                        }
                        Flavor::ArduPilot => MAV_RESULT_FAILED,
                        Flavor::Px4 => {
                            self.set_mode_internal(Mode::Takeoff);
                            let p = self.state.pos_ned_m;
                            self.target_ned_m = Some([p[0], p[1], -alt]);
                            MAV_RESULT_ACCEPTED
                        }
                    }
                }
            }
            _ => MAV_RESULT_UNSUPPORTED,
        };
        out.insert(0, header_ack(c.command, result, from));
        out
    }

    pub(super) fn setpoints_fresh(&self) -> bool {
        let timeout = match self.cfg.flavor {
            Flavor::Px4 => self.params.get("COM_OF_LOSS_T", 1.0),
            Flavor::ArduPilot => f64::INFINITY,
        };
        matches!(self.last_setpoint, Some((t, _)) if self.now_s - t <= timeout)
    }

    // BODY_NED and BODY_OFFSET_NED are deprecated in the MAVLink XML but are exactly the frame
    // numbers (8, 9) PX4 and ArduPilot accept.
    #[allow(deprecated)]
    pub(super) fn setpoint(&mut self, sp: &SET_POSITION_TARGET_LOCAL_NED_DATA) -> Vec<MavMessage> {
        let mut out = Vec::new();
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
            return out;
        }
        if ![sp.x, sp.y, sp.z].iter().all(|v| v.is_finite()) {
            out.push(self.statustext(
                MavSeverity::MAV_SEVERITY_WARNING,
                "position target ignored: non-finite position",
            ));
            return out;
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
            return out;
        };
        if !sp
            .type_mask
            .contains(PositionTargetTypemask::POSITION_TARGET_TYPEMASK_YAW_IGNORE)
            && sp.yaw.is_finite()
        {
            self.yaw_target_ned_rad = sp.yaw as f64;
        }
        match self.cfg.flavor {
            Flavor::Px4 => {
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
            Flavor::ArduPilot => {
                if self.mode != Mode::Guided {
                    return out; // silently ignored unless GUIDED
                }
                if let Some(alt) = self.takeoff_alt_m {
                    if self.state.altitude_m() < 0.95 * alt {
                        // A position target during the climb cancels the takeoff.
                        self.takeoff_alt_m = None;
                        let p = self.state.pos_ned_m;
                        self.target_ned_m = Some([p[0], p[1], 0.0]);
                        self.events.push(MockEvent::TakeoffCancelled);
                        out.push(
                            self.statustext(MavSeverity::MAV_SEVERITY_WARNING, "Takeoff cancelled"),
                        );
                        return out;
                    }
                    self.takeoff_alt_m = None;
                }
                self.last_setpoint = Some((self.now_s, target));
                self.target_ned_m = Some(target);
                self.target_vel_ned_mps = velocity;
            }
        }
        out
    }
}
