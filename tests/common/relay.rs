//! A UDP relay between infotrack and a mock autopilot that plays the attacker on the link:
//! it passes everything on, keeps what infotrack says to the ground station, and injects
//! frames of its own.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mavlink::dialects::ardupilotmega::*;
use mavlink::MavHeader;
use tokio::net::UdpSocket;

/// A frame of `msg` from (`sys`, `comp`), as the wire carries it.
pub fn frame(sys: u8, comp: u8, msg: &MavMessage) -> Vec<u8> {
    let mut bytes = Vec::new();
    let header = MavHeader {
        system_id: sys.into(),
        component_id: comp,
        sequence: 0,
    };
    mavlink::write_v2_msg(&mut bytes, header, msg).unwrap();
    bytes
}

/// A UDP relay between infotrack (which connects to its front port) and the mock autopilot;
/// it keeps the STATUSTEXTs infotrack sends and can add frames of its own.
pub struct Relay {
    /// Whether `inject` frames have been sent to infotrack.
    pub injected: Arc<AtomicBool>,
    /// The STATUSTEXTs infotrack sent toward the vehicle.
    pub texts: Arc<Mutex<Vec<String>>>,
}

/// A relay to the mock at `vehicle`, and the loopback port infotrack connects to, sending
/// `inject` to infotrack every 100 ms once the real vehicle's heartbeat has been passed on
/// (so that the first autopilot infotrack hears is the real one) and `after` has passed
/// since then. The relay binds its front
/// port itself: a port asked for free and bound later was once taken in between by a test
/// running beside it (AddrInUse in CI).
pub async fn relay(vehicle: u16, inject: Vec<Vec<u8>>, after: Duration) -> (Relay, u16) {
    relay_dropping(vehicle, inject, after, |_| false).await
}

/// [`relay`], which also drops what infotrack sends that `drop` picks (a vehicle that never
/// hears one kind of message).
pub async fn relay_dropping(
    vehicle: u16,
    inject: Vec<Vec<u8>>,
    after: Duration,
    drop: fn(&MavMessage) -> bool,
) -> (Relay, u16) {
    let front = Arc::new(UdpSocket::bind("127.0.0.1:0").await.unwrap());
    let front_port = front.local_addr().unwrap().port();
    let back = Arc::new(UdpSocket::bind("127.0.0.1:0").await.unwrap());
    back.connect(("127.0.0.1", vehicle)).await.unwrap();
    let companion: Arc<Mutex<Option<SocketAddr>>> = Arc::default();
    let vehicle_heard = Arc::new(AtomicBool::new(false));
    let r = Relay {
        injected: Arc::default(),
        texts: Arc::default(),
    };
    {
        let (front, back, companion) = (front.clone(), back.clone(), companion.clone());
        let texts = r.texts.clone();
        tokio::spawn(async move {
            let mut buf = [0u8; 2048];
            while let Ok((n, from)) = front.recv_from(&mut buf).await {
                *companion.lock().unwrap() = Some(from);
                let mut reader = mavlink::MavlinkReader::new(&buf[..n]);
                let msg = reader
                    .read_message::<MavMessage>(mavlink::MavlinkVersion::V2)
                    .ok()
                    .map(|(_, m)| m);
                if msg.as_ref().is_some_and(drop) {
                    continue;
                }
                let _ = back.send(&buf[..n]).await;
                if let Some(MavMessage::STATUSTEXT(t)) = msg {
                    let said = t.text.to_str().unwrap_or("").to_string();
                    texts.lock().unwrap().push(said);
                }
            }
        });
    }
    {
        let (front, companion, heard) = (front.clone(), companion.clone(), vehicle_heard.clone());
        tokio::spawn(async move {
            let mut buf = [0u8; 2048];
            while let Ok(n) = back.recv(&mut buf).await {
                let to = *companion.lock().unwrap();
                if let Some(to) = to {
                    let _ = front.send_to(&buf[..n], to).await;
                    let mut reader = mavlink::MavlinkReader::new(&buf[..n]);
                    if let Ok((_, MavMessage::HEARTBEAT(_))) =
                        reader.read_message::<MavMessage>(mavlink::MavlinkVersion::V2)
                    {
                        heard.store(true, Ordering::Relaxed);
                    }
                }
            }
        });
    }
    if !inject.is_empty() {
        let injected = r.injected.clone();
        tokio::spawn(async move {
            let mut heard_at = None;
            loop {
                tokio::time::sleep(Duration::from_millis(100)).await;
                let to = *companion.lock().unwrap();
                let heard = vehicle_heard.load(Ordering::Relaxed);
                if heard && heard_at.is_none() {
                    heard_at = Some(tokio::time::Instant::now());
                }
                let due = heard_at.is_some_and(|at| at.elapsed() >= after);
                if let (Some(to), true) = (to, due) {
                    for f in &inject {
                        let _ = front.send_to(f, to).await;
                    }
                    injected.store(true, Ordering::Relaxed);
                }
            }
        });
    }
    (r, front_port)
}
