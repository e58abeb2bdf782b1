//! Who has the vehicle: infotrack or the pilot (`daemon.engage`).
//!
//! With `auto` infotrack took off itself and has the vehicle from the start; it never takes
//! it back after the vehicle leaves the tracking mode (a failsafe or the pilot), and its
//! setpoints are ignored by the firmware outside that mode.
//!
//! With `pilot` the pilot takes off with the RC and hands over by switching to OFFBOARD
//! (PX4) or GUIDED (ArduPilot), from the RC or the ground station. infotrack commands only
//! while the vehicle is in that mode, lets go the moment it leaves (for any reason), and
//! takes over again only at the next switch. While it does not have the vehicle:
//! * PX4 needs a setpoint stream before OFFBOARD can be entered, so infotrack streams the
//!   vehicle's own position: PX4 ignores setpoints outside OFFBOARD, and a target where the
//!   vehicle already is cannot pull it anywhere once the pilot switches.
//! * ArduPilot enters GUIDED without a stream (it holds where it is), so infotrack sends
//!   nothing.
//!
//! Pure: the supervisor asks [`Engagement::update`] every tick and does what it says.

use crate::autopilot::modes::{Flavor, Mode};
use crate::config::Engage;

/// What changed at this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Change {
    /// Nothing.
    None,
    /// The vehicle entered the companion mode: infotrack commands from now on.
    Engaged,
    /// The vehicle left the companion mode (to `to`, if known): infotrack stops commanding.
    Released {
        /// The mode it went to.
        to: Option<Mode>,
    },
}

/// What the setpoint stream does while infotrack does not have the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdleStream {
    /// Stream the vehicle's own position (PX4: so that OFFBOARD can be entered).
    HoldHere,
    /// Send nothing (ArduPilot).
    Silent,
}

/// Whether infotrack has the vehicle.
#[derive(Debug, Clone)]
pub struct Engagement {
    engage: Engage,
    flavor: Flavor,
    engaged: bool,
}

impl Engagement {
    /// At the start of tracking: `auto` has the vehicle (it just took off), `pilot` waits
    /// for the switch.
    pub fn new(engage: Engage, flavor: Flavor) -> Self {
        Self {
            engage,
            flavor,
            engaged: engage == Engage::Auto,
        }
    }

    /// Whether infotrack commands the vehicle now.
    pub fn engaged(&self) -> bool {
        self.engaged
    }

    /// Follows the vehicle's mode; says when infotrack gains or loses the vehicle.
    pub fn update(&mut self, mode: Option<Mode>) -> Change {
        if self.engage == Engage::Auto {
            return Change::None;
        }
        let ours = mode == Some(Mode::companion_for(self.flavor));
        match (self.engaged, ours) {
            (false, true) => {
                self.engaged = true;
                Change::Engaged
            }
            (true, false) => {
                self.engaged = false;
                Change::Released { to: mode }
            }
            _ => Change::None,
        }
    }

    /// What to stream while not engaged.
    pub fn idle_stream(&self) -> IdleStream {
        match self.flavor {
            Flavor::Px4 => IdleStream::HoldHere,
            Flavor::ArduPilot => IdleStream::Silent,
        }
    }

    /// Whether the clean stop puts the vehicle in hold: only when infotrack has it; the
    /// pilot's mode is never changed.
    pub fn holds_at_stop(&self) -> bool {
        self.engaged
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_has_the_vehicle_and_never_takes_it_back() {
        let mut e = Engagement::new(Engage::Auto, Flavor::Px4);
        assert!(e.engaged());
        assert_eq!(e.update(Some(Mode::Position)), Change::None);
        assert_eq!(e.update(Some(Mode::Offboard)), Change::None);
        assert!(e.holds_at_stop());
    }

    #[test]
    fn pilot_engages_on_the_switch_and_releases_on_any_other_mode() {
        for (flavor, ours, idle) in [
            (Flavor::Px4, Mode::Offboard, IdleStream::HoldHere),
            (Flavor::ArduPilot, Mode::Guided, IdleStream::Silent),
        ] {
            let mut e = Engagement::new(Engage::Pilot, flavor);
            assert!(!e.engaged() && !e.holds_at_stop());
            assert_eq!(e.idle_stream(), idle);
            assert_eq!(e.update(Some(Mode::Position)), Change::None);
            assert_eq!(e.update(None), Change::None);
            assert_eq!(e.update(Some(ours)), Change::Engaged);
            assert!(e.engaged() && e.holds_at_stop());
            assert_eq!(e.update(Some(ours)), Change::None);
            assert_eq!(
                e.update(Some(Mode::ReturnToLaunch)),
                Change::Released {
                    to: Some(Mode::ReturnToLaunch)
                }
            );
            assert!(!e.engaged());
            // Not back by itself: only the next switch to the companion mode.
            assert_eq!(e.update(Some(Mode::Position)), Change::None);
            assert_eq!(e.update(Some(ours)), Change::Engaged);
        }
        // The other firmware's companion mode is not ours.
        let mut e = Engagement::new(Engage::Pilot, Flavor::Px4);
        assert_eq!(e.update(Some(Mode::Guided)), Change::None);
    }
}
