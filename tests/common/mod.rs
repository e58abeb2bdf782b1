//! Helpers shared by the integration tests that fly the mock autopilot.
#![allow(dead_code)]

use std::time::Duration;

use infotrack::autopilot::frames::PositionEnu;
use infotrack::autopilot::link::{LinkEvent, VehicleLink};
use infotrack::autopilot::modes::Mode;

/// A UDP port free at the time of asking.
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Flies to (x, y) ENU at `alt` and waits until the reported position is within 0.5 m.
pub async fn fly_to(link: &VehicleLink, x: f64, y: f64, alt: f64) {
    let p = PositionEnu {
        x_east_m: x,
        y_north_m: y,
        z_up_m: alt,
    };
    link.set_setpoint(p, 0.0).unwrap();
    link.wait_for(
        |s| {
            s.local_ned
                .map(|(_, n, _)| {
                    let e = n.to_enu();
                    (e.x_east_m - x).hypot(e.y_north_m - y) < 0.5 && (e.z_up_m - alt).abs() < 0.5
                })
                .unwrap_or(false)
        },
        &format!("reaching ({x}, {y}, {alt})"),
        Duration::from_secs(20),
    )
    .await
    .unwrap();
}

/// Waits for a mode change the link did not ask for, to `want`.
pub async fn expect_failsafe(
    link: &VehicleLink,
    rx: &mut tokio::sync::broadcast::Receiver<LinkEvent>,
    want: Mode,
) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(15);
    loop {
        match tokio::time::timeout_at(deadline, rx.recv()).await {
            Ok(Ok(LinkEvent::ModeChanged {
                to,
                commanded: false,
                ..
            })) if to == want => break,
            Ok(Ok(_)) | Ok(Err(_)) => continue,
            Err(_) => panic!("no failsafe to {want:?}; state {:?}", link.state().mode),
        }
    }
    assert!(link
        .state()
        .unexpected_mode_changes
        .iter()
        .any(|(_, to)| *to == want));
}
