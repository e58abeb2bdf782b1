//! Between the camera's view and the vehicle's nose.
//!
//! The tracker thinks in the camera's view ([`View`](crate::world::camera::View): which way
//! its image's top faces); the vehicle flies its nose. A camera turned on its mount by yaw psi
//! (`daemon.camera_mount_rpy_rad`) faces the nose's heading plus psi
//! ([`view_yaw_enu_of_nose`], how the daemon reads every frame's view from ATTITUDE); to
//! face a view, the nose flies it less psi ([`nose_yaw_enu_for_view`], what every setpoint
//! carries). A setpoint that carried yaw ENU 0 (the nose east) while the model held the view
//! north would be wrong: on a real vehicle the image lay across the model and a missed
//! detection removed hypotheses the camera had not looked at (the synthetic camera rendered
//! at the model's heading, so no simulation showed it).

use crate::config::Config;
use crate::frames::{yaw_enu_to_ned, yaw_ned_to_enu};
use crate::world::camera::NORTH_VIEW_YAW_ENU_RAD;

/// The heading the camera's image faces, world ENU yaw (rad, [`View::yaw_enu_rad`]), on a
/// vehicle whose nose is at `nose_yaw_ned_rad` (local NED, ATTITUDE's yaw) with its camera
/// turned on its mount by `mount_yaw_body_rad`.
pub fn view_yaw_enu_of_nose(nose_yaw_ned_rad: f64, mount_yaw_body_rad: f64) -> f64 {
    yaw_ned_to_enu(nose_yaw_ned_rad + mount_yaw_body_rad)
}

/// The nose's heading, world ENU yaw (rad, what a setpoint carries), at which a camera turned
/// on its mount by `mount_yaw_body_rad` faces `view_yaw_enu_rad`.
pub fn nose_yaw_enu_for_view(view_yaw_enu_rad: f64, mount_yaw_body_rad: f64) -> f64 {
    yaw_ned_to_enu(yaw_enu_to_ned(view_yaw_enu_rad) - mount_yaw_body_rad)
}

/// The nose's heading at the start setpoint, world ENU rad: the north view (the heading
/// the tracker begins with) for this config's camera mount.
pub fn start_yaw_enu_rad(cfg: &Config) -> f64 {
    nose_yaw_enu_for_view(NORTH_VIEW_YAW_ENU_RAD, cfg.daemon.camera_mount_rpy_rad[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frames::{yaw_enu_to_ned, VehiclePoseNed};
    use crate::vision::camera_model::{CameraModel, CameraMount, Intrinsics};
    use crate::world::camera::{Footprint, View};
    use crate::world::geometry::Enu2;

    const ALTITUDE_M: f64 = 45.0;
    const FOV_X_RAD: f64 = 1.14;

    /// The ground points (world ENU, relative to the vehicle) of the image's right-edge
    /// centre and top-edge centre, for a vehicle at `yaw_enu_rad`.
    fn image_edges_on_ground(mount_yaw: f64, yaw_enu_rad: f64) -> (Enu2, Enu2) {
        let intrinsics = Intrinsics::ideal(1280, 720, FOV_X_RAD);
        let cam = CameraModel {
            intrinsics: intrinsics.clone(),
            mount: CameraMount::from_angles(0.0, 0.0, mount_yaw, [0.0; 3]),
        };
        let at = Enu2::new(120.0, -40.0);
        let mut pose = VehiclePoseNed::level_above(&at, ALTITUDE_M);
        pose.yaw_rad = yaw_enu_to_ned(yaw_enu_rad);
        let ground = |u: f64, v: f64| {
            let g = cam.pixel_to_ground_enu(u, v, &pose).expect("looks down");
            Enu2::new(g[0], g[1]) - at
        };
        let w = intrinsics.width_px as f64;
        (
            ground(w - 0.5, intrinsics.cy_px),
            ground(intrinsics.cx_px, -0.5),
        )
    }

    #[test]
    fn at_the_flown_heading_the_image_lies_as_the_footprint_model_has_it() {
        let fov_y = 2.0 * ((720.0 / 1280.0) * (0.5 * FOV_X_RAD).tan()).atan();
        let fp = Footprint::from_fov(ALTITUDE_M, FOV_X_RAD, fov_y);
        for mount_yaw in [0.0, 0.3, std::f64::consts::FRAC_PI_2, -2.0] {
            let nose = nose_yaw_enu_for_view(NORTH_VIEW_YAW_ENU_RAD, mount_yaw);
            let (right, top) = image_edges_on_ground(mount_yaw, nose);
            // The image's right edge: east, at the footprint's half width.
            assert!(
                (right.x - fp.half_width_m).abs() < 0.05,
                "{mount_yaw}: {right:?}"
            );
            assert!(right.y.abs() < 0.05, "{mount_yaw}: {right:?}");
            // Its top edge: north, at the footprint's half height.
            assert!(
                (top.y - fp.half_height_m).abs() < 0.05,
                "{mount_yaw}: {top:?}"
            );
            assert!(top.x.abs() < 0.05, "{mount_yaw}: {top:?}");
        }
    }

    #[test]
    fn the_old_heading_east_turned_the_image_across_the_model() {
        // Yaw ENU 0, what every setpoint carried before: the image's right edge falls south.
        let (right, top) = image_edges_on_ground(0.0, 0.0);
        assert!(right.y < -20.0 && right.x.abs() < 0.05, "{right:?}");
        assert!(top.x > 10.0, "{top:?}");
        let nose = nose_yaw_enu_for_view(NORTH_VIEW_YAW_ENU_RAD, 0.0);
        assert!((nose - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn a_turned_view_is_flown_with_the_image_where_the_view_has_it() {
        let fov_y = 2.0 * ((720.0 / 1280.0) * (0.5 * FOV_X_RAD).tan()).atan();
        let fp = Footprint::from_fov(ALTITUDE_M, FOV_X_RAD, fov_y);
        for mount_yaw in [0.0, 0.3, -2.0] {
            for view_yaw in [0.0, 1.0, -2.5, std::f64::consts::FRAC_PI_2] {
                let nose_enu = nose_yaw_enu_for_view(view_yaw, mount_yaw);
                let (right, top) = image_edges_on_ground(mount_yaw, nose_enu);
                let view = View::new(Enu2::zeros(), view_yaw);
                let want_right = view.from_view_axes(fp.half_width_m, 0.0);
                let want_top = view.from_view_axes(0.0, fp.half_height_m);
                assert!(
                    (right - want_right).norm() < 0.05,
                    "{right:?} {want_right:?}"
                );
                assert!((top - want_top).norm() < 0.05, "{top:?} {want_top:?}");
                // And the view is read back from the nose's ATTITUDE yaw.
                let back = view_yaw_enu_of_nose(yaw_enu_to_ned(nose_enu), mount_yaw);
                assert!(crate::frames::wrap_angle(back - view_yaw).abs() < 1e-9);
            }
        }
    }
}
