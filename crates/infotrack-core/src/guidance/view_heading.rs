//! Which way the camera's image faces: the heading every command carries and every EER
//! candidate is judged at.
//!
//! The paper's agent keeps one heading (`north`, the lab's and the default). A nadir view
//! is a rectangle (58 x 31 m from 45 m with the field configs' 1280x720 camera), and a
//! road-bound belief is a line along a road: with the view's long side along the way the
//! vehicle flies (`along_track`; chasing a car, along its road) the view holds up to 58 m of
//! the road instead of 31 m when the road runs north-south. Measured (BENCHMARKS.md): level on average, so the default stays `north`. The other way round
//! (the image's top along the way flown, its long side across the track) was 7.7 points of
//! FOV worse over 21 worlds.

use std::f64::consts::{FRAC_PI_2, PI};

use crate::frames::{wrap_angle, Enu2};
use crate::world::camera::{View, NORTH_VIEW_YAW_ENU_RAD};

/// Below this speed a command's velocity says nothing about its heading, m/s.
const MIN_HEADING_SPEED_MPS: f64 = 1.0;

/// How the view's heading is chosen (`guidance.view_heading`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ViewHeading {
    /// Always north (the image's width along world east): the paper's constant heading.
    North,
    /// The image's width, its long side, along the direction of travel: the command's
    /// velocity (the target's, riding along with it), or the way to its setpoint; near the
    /// setpoint and at rest, the heading the view has ([`HeadingRule::yaw_enu_rad`]).
    AlongTrack,
    /// EER chooses: each candidate is judged at the `along_track` heading and a quarter turn
    /// from it, and the plan flies the view that scores higher ([`HeadingRule::views_over`]).
    /// A long side across the track sees both exits of a covered junction whose exits lie
    /// on either side of the way the car went in. Laws other than EER fly `along_track`.
    Informed,
}

/// A heading name that names none.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` (expected north, along_track or informed)")]
pub struct UnknownViewHeading(pub String);

impl std::str::FromStr for ViewHeading {
    type Err = UnknownViewHeading;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "north" => Ok(Self::North),
            "along_track" => Ok(Self::AlongTrack),
            "informed" => Ok(Self::Informed),
            other => Err(UnknownViewHeading(other.to_string())),
        }
    }
}

/// The rule with its scale: how far a setpoint must be for the way to it to set the heading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingRule {
    /// The rule.
    pub kind: ViewHeading,
    /// Nearer than this the heading stays (a hover does not spin on a metre's jitter), m.
    pub settle_m: f64,
}

impl HeadingRule {
    /// The paper's constant heading.
    pub fn north() -> Self {
        Self {
            kind: ViewHeading::North,
            settle_m: 0.0,
        }
    }

    /// The view's heading, world ENU yaw (rad), for a vehicle seeing `now` that flies to
    /// `setpoint_enu` moving at `velocity_enu` (m/s). A footprint turned half a turn is the
    /// same rectangle: of the two headings the nearer is taken, so the vehicle never turns
    /// more than a quarter turn.
    pub fn yaw_enu_rad(&self, now: &View, setpoint_enu: &Enu2, velocity_enu: &Enu2) -> f64 {
        match self.kind {
            ViewHeading::North => NORTH_VIEW_YAW_ENU_RAD,
            ViewHeading::AlongTrack | ViewHeading::Informed => {
                let to_go = setpoint_enu - now.centre_enu;
                let way = if velocity_enu.norm() >= MIN_HEADING_SPEED_MPS {
                    velocity_enu.y.atan2(velocity_enu.x)
                } else if to_go.norm() > self.settle_m {
                    to_go.y.atan2(to_go.x)
                } else {
                    return now.yaw_enu_rad;
                };
                // The width (body right) along the way: the image's top a quarter turn left.
                nearer_of_the_two(way + FRAC_PI_2, now.yaw_enu_rad)
            }
        }
    }

    /// The view a vehicle seeing `now` will have over the candidate waypoint `candidate_enu`:
    /// there, turned for the way it flew to it, or, riding along with the target at
    /// `over_target_velocity_enu`, for the target's track.
    pub fn view_over(
        &self,
        now: &View,
        candidate_enu: &Enu2,
        over_target_velocity_enu: Option<Enu2>,
    ) -> View {
        let v = over_target_velocity_enu.unwrap_or_else(Enu2::zeros);
        View::new(*candidate_enu, self.yaw_enu_rad(now, candidate_enu, &v))
    }

    /// The views EER judges over `candidate_enu`: [`Self::view_over`]'s, and under
    /// `informed` also the one a quarter turn from it (of its two equal footprints, the
    /// nearer `now`'s heading), second, so that of two equal scores the first stays.
    pub fn views_over(
        &self,
        now: &View,
        candidate_enu: &Enu2,
        over_target_velocity_enu: Option<Enu2>,
    ) -> impl Iterator<Item = View> {
        let first = self.view_over(now, candidate_enu, over_target_velocity_enu);
        let turned = (self.kind == ViewHeading::Informed).then(|| {
            let yaw = nearer_of_the_two(first.yaw_enu_rad + FRAC_PI_2, now.yaw_enu_rad);
            View::new(*candidate_enu, yaw)
        });
        std::iter::once(first).chain(turned)
    }
}

/// `wanted` or `wanted` + pi, whichever is nearer `now` (world ENU yaw, rad): the same
/// footprint either way.
fn nearer_of_the_two(wanted: f64, now: f64) -> f64 {
    let d = wrap_angle(wanted - now);
    if d > FRAC_PI_2 {
        wrap_angle(wanted - PI)
    } else if d < -FRAC_PI_2 {
        wrap_angle(wanted + PI)
    } else {
        wrap_angle(wanted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn north_never_turns_and_along_track_lays_the_long_side_along_the_way() {
        let now = View::new(Enu2::new(10.0, 0.0), 1.0);
        let north = HeadingRule::north();
        let far = Enu2::new(50.0, 0.0);
        assert_eq!(
            north.yaw_enu_rad(&now, &far, &Enu2::new(0.0, -9.0)),
            NORTH_VIEW_YAW_ENU_RAD
        );
        let along = HeadingRule {
            kind: ViewHeading::AlongTrack,
            settle_m: 5.0,
        };
        // The velocity first: north-west; the width along it, the top to its left
        // (south-west, -3/4 pi) or, the same footprint, north-east (pi/4), nearer 1 rad.
        let v = Enu2::new(-3.0, 3.0);
        let yaw = along.yaw_enu_rad(&now, &far, &v);
        assert!((yaw - 0.25 * PI).abs() < 1e-12, "{yaw}");
        let view = View::new(Enu2::zeros(), yaw);
        let (across, up) = view.to_view_axes(&v);
        assert!(up.abs() < 1e-9 && across.abs() > 4.0, "{across} {up}");
        // Driving south-east: the same footprint, the same heading.
        assert!((along.yaw_enu_rad(&now, &far, &(-v)) - yaw).abs() < 1e-12);
        // At rest, the way to the setpoint (east): the top north.
        let east = along.yaw_enu_rad(&now, &far, &Enu2::zeros());
        assert!((east - FRAC_PI_2).abs() < 1e-12, "{east}");
        // Near it, the heading stays.
        let near = along.view_over(&now, &Enu2::new(13.0, 0.0), None);
        assert_eq!(near.yaw_enu_rad, 1.0);
        assert_eq!(near.centre_enu, Enu2::new(13.0, 0.0));
        // Riding along with a target driving south: the width north-south.
        let riding = along.view_over(&now, &Enu2::new(13.0, 0.0), Some(Enu2::new(0.0, -8.0)));
        assert!(
            wrap_angle(riding.yaw_enu_rad).abs() < 1e-12,
            "{}",
            riding.yaw_enu_rad
        );
        // Never more than a quarter turn from where it faces.
        for k in 0..24 {
            let a = k as f64 * PI / 12.0;
            let to = Enu2::new(10.0 + 40.0 * a.cos(), 40.0 * a.sin());
            let y = along.yaw_enu_rad(&now, &to, &Enu2::zeros());
            assert!(wrap_angle(y - 1.0).abs() <= FRAC_PI_2 + 1e-12, "{a}: {y}");
        }
    }

    #[test]
    fn informed_offers_the_rules_view_and_a_quarter_turn_from_it() {
        let now = View::new(Enu2::new(10.0, 0.0), 1.0);
        let at = Enu2::new(80.0, 0.0);
        for kind in [ViewHeading::North, ViewHeading::AlongTrack] {
            let rule = HeadingRule {
                kind,
                settle_m: 5.0,
            };
            let views: Vec<View> = rule.views_over(&now, &at, None).collect();
            assert_eq!(views, vec![rule.view_over(&now, &at, None)]);
        }
        let along = HeadingRule {
            kind: ViewHeading::AlongTrack,
            settle_m: 5.0,
        };
        let informed = HeadingRule {
            kind: ViewHeading::Informed,
            ..along
        };
        for velocity in [None, Some(Enu2::new(0.0, -8.0))] {
            let views: Vec<View> = informed.views_over(&now, &at, velocity).collect();
            assert_eq!(views.len(), 2);
            // First the along-track view; then a quarter turn from it, the turn of the two
            // equal footprints nearer where the vehicle faces.
            assert_eq!(views[0], along.view_over(&now, &at, velocity));
            let turn = wrap_angle(views[1].yaw_enu_rad - views[0].yaw_enu_rad);
            assert!((turn.abs() - FRAC_PI_2).abs() < 1e-12, "{turn}");
            assert!(wrap_angle(views[1].yaw_enu_rad - 1.0).abs() <= FRAC_PI_2 + 1e-12);
            assert!(views.iter().all(|v| v.centre_enu == at));
        }
    }

    #[test]
    fn names_parse_and_a_wrong_one_says_what_is_expected() {
        assert_eq!(
            "along_track".parse::<ViewHeading>(),
            Ok(ViewHeading::AlongTrack)
        );
        assert_eq!("informed".parse::<ViewHeading>(), Ok(ViewHeading::Informed));
        assert_eq!("north".parse::<ViewHeading>(), Ok(ViewHeading::North));
        let e = "nose".parse::<ViewHeading>().unwrap_err().to_string();
        assert!(e.contains("nose") && e.contains("along_track"), "{e}");
    }
}
