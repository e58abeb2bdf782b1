//! Fuzzing the MAVLink input path (bounded, in the test suite): arbitrary bytes through the
//! frame reader, and arbitrary payloads decoded as the messages infotrack's link and the
//! mock read (NaN, infinities, out-of-range enums and ids included), fed to the link's
//! vehicle state and to the mock autopilot. Nothing may panic, the link's state must stay
//! finite and locked to one vehicle, and the mock's vehicle must stay finite.

use std::io::Cursor;

use infotrack::autopilot::link::fuzz::{feed, LinkUnderTest};
use infotrack::autopilot::modes::Flavor;
use infotrack::mock::{MockAutopilot, MockConfig};
use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{MavHeader, MavlinkVersion, Message};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};

/// The messages either side reads.
const IDS: [u32; 17] = [
    0, 1, 20, 21, 22, 23, 30, 32, 33, 66, 75, 76, 77, 84, 242, 245, 253,
];

fn messages() -> impl Strategy<Value = Vec<(u8, u8, MavMessage)>> {
    proptest::collection::vec(
        (
            prop_oneof![Just(1u8), Just(42u8), any::<u8>()],
            prop_oneof![Just(1u8), any::<u8>()],
            proptest::sample::select(IDS.to_vec()),
            proptest::collection::vec(any::<u8>(), 0..280),
        ),
        1..60,
    )
    .prop_map(|raw| {
        raw.into_iter()
            .filter_map(|(sys, comp, id, payload)| {
                MavMessage::parse(MavlinkVersion::V2, id, &payload)
                    .ok()
                    .map(|m| (sys, comp, m))
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn any_bytes_through_the_frame_reader_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..4096)) {
        let mut reader = mavlink::MavlinkReader::new(Cursor::new(bytes));
        for _ in 0..64 {
            if reader.read_any_message::<MavMessage>().is_err() {
                break;
            }
        }
    }

    #[test]
    fn the_link_state_stays_finite_and_locked_whatever_arrives(msgs in messages()) {
        let mut link = LinkUnderTest::new();
        // The lock: the first autopilot heard, whose own system's component 1 (the flight
        // controller) takes over if it speaks later; no other system ever.
        let mut first_autopilot: Option<(u8, u8)> = None;
        for (s, c, m) in &msgs {
            if let MavMessage::HEARTBEAT(h) = m {
                let autopilot = matches!(
                    h.autopilot,
                    mavlink::dialects::ardupilotmega::MavAutopilot::MAV_AUTOPILOT_PX4
                        | mavlink::dialects::ardupilotmega::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA
                );
                match first_autopilot {
                    None if autopilot => first_autopilot = Some((*s, *c)),
                    Some((ls, _)) if autopilot && ls == *s && *c == 1 => {
                        first_autopilot = Some((*s, 1))
                    }
                    _ => {}
                }
            }
        }
        for (sys, comp, m) in &msgs {
            feed(&mut link, MavHeader { system_id: *sys as u32, component_id: *comp, sequence: 0 }, m);
        }
        let s = link.state();
        prop_assert_eq!(s.address, first_autopilot);
        if let Some((_, p, v)) = s.local_ned {
            prop_assert!(p.x_north_m.is_finite() && p.y_east_m.is_finite() && p.z_down_m.is_finite());
            prop_assert!(v.iter().all(|x| x.is_finite()));
        }
        if let Some((_, a)) = s.attitude {
            prop_assert!(a.iter().all(|x| x.is_finite()));
        }
    }

    #[test]
    fn the_mock_survives_whatever_a_client_sends(msgs in messages(), px4 in any::<bool>()) {
        let flavor = if px4 { Flavor::Px4 } else { Flavor::ArduPilot };
        let mut m = MockAutopilot::new(MockConfig::new(flavor), 0.0);
        let mut t = 0.0;
        for (sys, comp, msg) in &msgs {
            t += 0.05;
            let h = MavHeader { system_id: *sys as u32, component_id: *comp, sequence: 0 };
            let _ = m.handle(t, &h, msg);
            let _ = m.tick(t);
        }
        let p = m.position_ned_m();
        prop_assert!(p.iter().all(|x| x.is_finite()), "{:?}", p);
    }
}

#[test]
fn the_message_ids_fuzzed_are_the_ones_decoded() {
    // Guards the fuzz against a list of ids the dialect does not know (all would fail to
    // parse and nothing would be fed).
    for id in IDS {
        let m = MavMessage::default_message_from_id(id).expect("a known id");
        assert_eq!(m.message_id(), id);
        // A short payload is zero-extended (MAVLink 2 truncation), so random payloads of
        // any length decode unless an enum field is out of range: some must decode.
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(id as u64);
        let decoded = (0..500)
            .filter(|_| {
                let len = rng.gen_range(0..280);
                let payload: Vec<u8> = (0..len).map(|_| rng.gen()).collect();
                MavMessage::parse(MavlinkVersion::V2, id, &payload).is_ok()
            })
            .count();
        assert!(decoded > 0, "message {id}: no random payload decodes");
    }
}
