//! Flight modes as PX4 and ArduCopter encode them in HEARTBEAT.custom_mode and
//! MAV_CMD_DO_SET_MODE.

use std::fmt;

/// Which autopilot firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Flavor {
    /// PX4 (MAV_AUTOPILOT_PX4 = 12).
    Px4,
    /// ArduPilot Copter (MAV_AUTOPILOT_ARDUPILOTMEGA = 3).
    ArduPilot,
}

impl fmt::Display for Flavor {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Px4 => "px4",
            Self::ArduPilot => "ardupilot",
        })
    }
}

/// A flavour name that names no firmware.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown autopilot flavour `{0}` (expected px4 or ardupilot)")]
pub struct UnknownFlavor(pub String);

impl std::str::FromStr for Flavor {
    type Err = UnknownFlavor;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "px4" => Ok(Self::Px4),
            "ardupilot" => Ok(Self::ArduPilot),
            other => Err(UnknownFlavor(other.to_string())),
        }
    }
}

/// The modes infotrack uses or must recognise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// PX4 POSCTL / ArduPilot LOITER-like manual position hold by RC.
    Position,
    /// PX4 AUTO.TAKEOFF.
    Takeoff,
    /// PX4 AUTO.LOITER / ArduPilot LOITER: hold position (the clean-stop mode).
    Hold,
    /// PX4 AUTO.RTL / ArduPilot RTL.
    ReturnToLaunch,
    /// PX4 AUTO.LAND / ArduPilot LAND.
    Land,
    /// PX4 OFFBOARD.
    Offboard,
    /// ArduPilot GUIDED.
    Guided,
    /// ArduPilot BRAKE.
    Brake,
    /// PX4 ALTCTL / ArduPilot ALT_HOLD.
    Altitude,
    /// PX4 STABILIZED / ArduPilot STABILIZE.
    Stabilized,
    /// PX4 MANUAL.
    Manual,
    /// A mode number infotrack does not name.
    Other(u32),
}

/// The mode in words for people (the run summary, messages): the name both firmwares'
/// ground stations show where they agree, the pair where they differ.
impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Mode::Position => f.write_str("POSITION (PX4 POSCTL / ArduPilot LOITER)"),
            Mode::Takeoff => f.write_str("TAKEOFF"),
            Mode::Hold => f.write_str("HOLD (PX4 AUTO.LOITER / ArduPilot LOITER)"),
            Mode::ReturnToLaunch => f.write_str("RTL"),
            Mode::Land => f.write_str("LAND"),
            Mode::Offboard => f.write_str("OFFBOARD"),
            Mode::Guided => f.write_str("GUIDED"),
            Mode::Brake => f.write_str("BRAKE"),
            Mode::Altitude => f.write_str("ALTITUDE (PX4 ALTCTL / ArduPilot ALT_HOLD)"),
            Mode::Stabilized => f.write_str("STABILIZED"),
            Mode::Manual => f.write_str("MANUAL"),
            Mode::Other(n) => write!(f, "mode {n}"),
        }
    }
}

/// PX4 main modes.
pub mod px4 {
    /// MANUAL.
    pub const MANUAL: u8 = 1;
    /// ALTCTL.
    pub const ALTCTL: u8 = 2;
    /// POSCTL.
    pub const POSCTL: u8 = 3;
    /// AUTO.
    pub const AUTO: u8 = 4;
    /// OFFBOARD.
    pub const OFFBOARD: u8 = 6;
    /// STABILIZED.
    pub const STABILIZED: u8 = 7;
    /// AUTO sub-mode TAKEOFF.
    pub const AUTO_TAKEOFF: u8 = 2;
    /// AUTO sub-mode LOITER.
    pub const AUTO_LOITER: u8 = 3;
    /// AUTO sub-mode RTL.
    pub const AUTO_RTL: u8 = 5;
    /// AUTO sub-mode LAND.
    pub const AUTO_LAND: u8 = 6;

    /// custom_mode = (sub_mode << 24) | (main_mode << 16).
    pub fn encode(main: u8, sub: u8) -> u32 {
        ((sub as u32) << 24) | ((main as u32) << 16)
    }

    /// (main, sub) from custom_mode.
    pub fn decode(custom_mode: u32) -> (u8, u8) {
        (
            ((custom_mode >> 16) & 0xff) as u8,
            ((custom_mode >> 24) & 0xff) as u8,
        )
    }
}

/// ArduCopter mode numbers.
pub mod copter {
    /// STABILIZE.
    pub const STABILIZE: u32 = 0;
    /// ALT_HOLD.
    pub const ALT_HOLD: u32 = 2;
    /// AUTO.
    pub const AUTO: u32 = 3;
    /// GUIDED.
    pub const GUIDED: u32 = 4;
    /// LOITER.
    pub const LOITER: u32 = 5;
    /// RTL.
    pub const RTL: u32 = 6;
    /// LAND.
    pub const LAND: u32 = 9;
    /// BRAKE.
    pub const BRAKE: u32 = 17;
    /// SMART_RTL.
    pub const SMART_RTL: u32 = 21;
}

impl Mode {
    /// The mode that holds the vehicle where it is, altitude included, whatever the RC
    /// does: PX4's AUTO.LOITER; ArduCopter's BRAKE (its LOITER reads the pilot's throttle
    /// and, with no RC or a lost one, descends to the ground: seen in SITL).
    pub fn hold_for(flavor: Flavor) -> Mode {
        match flavor {
            Flavor::Px4 => Mode::Hold,
            Flavor::ArduPilot => Mode::Brake,
        }
    }

    /// The mode in which the vehicle follows a companion's setpoints: PX4 OFFBOARD,
    /// ArduPilot GUIDED.
    pub fn companion_for(flavor: Flavor) -> Mode {
        match flavor {
            Flavor::Px4 => Mode::Offboard,
            Flavor::ArduPilot => Mode::Guided,
        }
    }

    /// HEARTBEAT.custom_mode for this mode on `flavor`; `None` if the firmware has no such mode.
    pub fn custom_mode(&self, flavor: Flavor) -> Option<u32> {
        use Mode::*;
        match flavor {
            Flavor::Px4 => Some(match self {
                Manual => px4::encode(px4::MANUAL, 0),
                Altitude => px4::encode(px4::ALTCTL, 0),
                Position => px4::encode(px4::POSCTL, 0),
                Stabilized => px4::encode(px4::STABILIZED, 0),
                Offboard => px4::encode(px4::OFFBOARD, 0),
                Takeoff => px4::encode(px4::AUTO, px4::AUTO_TAKEOFF),
                Hold => px4::encode(px4::AUTO, px4::AUTO_LOITER),
                ReturnToLaunch => px4::encode(px4::AUTO, px4::AUTO_RTL),
                Land => px4::encode(px4::AUTO, px4::AUTO_LAND),
                Other(m) => *m,
                Guided | Brake => return None,
            }),
            Flavor::ArduPilot => Some(match self {
                Stabilized => copter::STABILIZE,
                Altitude => copter::ALT_HOLD,
                Guided => copter::GUIDED,
                Hold | Position => copter::LOITER,
                ReturnToLaunch => copter::RTL,
                Land => copter::LAND,
                Brake => copter::BRAKE,
                Other(m) => *m,
                Manual | Offboard | Takeoff => return None,
            }),
        }
    }

    /// The mode a HEARTBEAT.custom_mode means on `flavor`.
    pub fn from_custom_mode(flavor: Flavor, custom_mode: u32) -> Mode {
        use Mode::*;
        match flavor {
            Flavor::Px4 => match px4::decode(custom_mode) {
                (px4::MANUAL, _) => Manual,
                (px4::ALTCTL, _) => Altitude,
                (px4::POSCTL, _) => Position,
                (px4::STABILIZED, _) => Stabilized,
                (px4::OFFBOARD, _) => Offboard,
                (px4::AUTO, px4::AUTO_TAKEOFF) => Takeoff,
                (px4::AUTO, px4::AUTO_LOITER) => Hold,
                (px4::AUTO, px4::AUTO_RTL) => ReturnToLaunch,
                (px4::AUTO, px4::AUTO_LAND) => Land,
                _ => Other(custom_mode),
            },
            Flavor::ArduPilot => match custom_mode {
                copter::STABILIZE => Stabilized,
                copter::ALT_HOLD => Altitude,
                copter::GUIDED => Guided,
                copter::LOITER => Hold,
                copter::RTL => ReturnToLaunch,
                copter::LAND => Land,
                copter::BRAKE => Brake,
                other => Other(other),
            },
        }
    }

    /// DO_SET_MODE params 2 and 3 (main and sub mode for PX4, mode number for ArduPilot).
    pub fn do_set_mode_params(&self, flavor: Flavor) -> Option<(f32, f32)> {
        let cm = self.custom_mode(flavor)?;
        Some(match flavor {
            Flavor::Px4 => {
                let (main, sub) = px4::decode(cm);
                (main as f32, sub as f32)
            }
            Flavor::ArduPilot => (cm as f32, 0.0),
        })
    }

    /// The mode DO_SET_MODE params 2 and 3 ask for.
    pub fn from_do_set_mode(flavor: Flavor, p2: f32, p3: f32) -> Mode {
        match flavor {
            Flavor::Px4 => Self::from_custom_mode(Flavor::Px4, px4::encode(p2 as u8, p3 as u8)),
            Flavor::ArduPilot => Self::from_custom_mode(Flavor::ArduPilot, p2 as u32),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn px4_encodings_match_what_px4_sends() {
        assert_eq!(Mode::Offboard.custom_mode(Flavor::Px4), Some(0x0006_0000));
        assert_eq!(Mode::Hold.custom_mode(Flavor::Px4), Some(0x0304_0000));
        assert_eq!(
            Mode::ReturnToLaunch.custom_mode(Flavor::Px4),
            Some(0x0504_0000)
        );
        assert_eq!(Mode::Takeoff.custom_mode(Flavor::Px4), Some(0x0204_0000));
        assert_eq!(Mode::Land.custom_mode(Flavor::Px4), Some(0x0604_0000));
        assert_eq!(Mode::Hold.do_set_mode_params(Flavor::Px4), Some((4.0, 3.0)));
    }

    #[test]
    fn ardupilot_mode_numbers() {
        assert_eq!(Mode::Guided.custom_mode(Flavor::ArduPilot), Some(4));
        assert_eq!(Mode::Hold.custom_mode(Flavor::ArduPilot), Some(5));
        assert_eq!(Mode::Brake.custom_mode(Flavor::ArduPilot), Some(17));
        assert_eq!(Mode::Offboard.custom_mode(Flavor::ArduPilot), None);
        assert_eq!(Mode::Guided.custom_mode(Flavor::Px4), None);
    }

    #[test]
    fn encode_decode_round_trip() {
        for flavor in [Flavor::Px4, Flavor::ArduPilot] {
            for m in [
                Mode::Hold,
                Mode::Offboard,
                Mode::Guided,
                Mode::ReturnToLaunch,
                Mode::Land,
                Mode::Takeoff,
                Mode::Brake,
                Mode::Altitude,
            ] {
                if let Some(cm) = m.custom_mode(flavor) {
                    assert_eq!(Mode::from_custom_mode(flavor, cm), m, "{flavor} {m:?}");
                    let (p2, p3) = m.do_set_mode_params(flavor).unwrap();
                    assert_eq!(Mode::from_do_set_mode(flavor, p2, p3), m);
                }
            }
        }
    }
}
