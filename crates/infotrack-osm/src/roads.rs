//! Which OSM ways a car may drive, and which way.

use crate::read::Way;

/// The highway classes a car drives on (OSM `highway=*`): the road network proper, its
/// links and residential and service streets (not parking aisles or driveways).
const DRIVABLE: &[&str] = &[
    "motorway",
    "trunk",
    "primary",
    "secondary",
    "tertiary",
    "unclassified",
    "residential",
    "living_street",
    "service",
    "road",
    "motorway_link",
    "trunk_link",
    "primary_link",
    "secondary_link",
    "tertiary_link",
];

/// Service roads a car passes through only to park or reach one house.
const SERVICE_NOT_DRIVEN: &[&str] = &[
    "parking_aisle",
    "driveway",
    "drive-through",
    "emergency_access",
];

/// Access values that close a road to a private car.
const NO_ACCESS: &[&str] = &[
    "no",
    "private",
    "agricultural",
    "forestry",
    "emergency",
    "delivery",
];

/// Why a way with a `highway` tag is not a road of the world.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum NotDriven {
    /// Not a class a car drives on (footway, cycleway, path, track, steps, ...).
    Class,
    /// Closed to private cars (`access`, `motor_vehicle`, `motorcar`).
    Access,
    /// An area, or a way whose direction changes (`oneway=reversible`).
    Shape,
}

/// Which way a car may drive a road, along its nodes' order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Along the way.
    Forward,
    /// Against it (`oneway=-1`).
    Backward,
    /// Both.
    Both,
}

/// Whether a car may drive `way`, and if so which way.
pub fn drivable(way: &Way) -> Result<Direction, NotDriven> {
    let class = way.tag("highway").unwrap_or("");
    if !DRIVABLE.contains(&class) {
        return Err(NotDriven::Class);
    }
    if class == "service"
        && way
            .tag("service")
            .is_some_and(|s| SERVICE_NOT_DRIVEN.contains(&s))
    {
        return Err(NotDriven::Class);
    }
    // The most specific access tag decides: motorcar, then motor_vehicle, then access.
    let access = ["motorcar", "motor_vehicle", "access"]
        .iter()
        .find_map(|k| way.tag(k));
    if access.is_some_and(|a| NO_ACCESS.contains(&a)) {
        return Err(NotDriven::Access);
    }
    if way.tag("area") == Some("yes") {
        return Err(NotDriven::Shape);
    }
    direction(way, class)
}

/// The direction `oneway` gives, or that a roundabout or a motorway implies.
fn direction(way: &Way, class: &str) -> Result<Direction, NotDriven> {
    match way.tag("oneway") {
        Some("yes" | "true" | "1") => Ok(Direction::Forward),
        Some("-1" | "reverse") => Ok(Direction::Backward),
        Some("no" | "false" | "0") => Ok(Direction::Both),
        Some("reversible" | "alternating") => Err(NotDriven::Shape),
        _ => {
            let roundabout = matches!(way.tag("junction"), Some("roundabout" | "circular"));
            let motorway = matches!(class, "motorway" | "motorway_link");
            Ok(if roundabout || motorway {
                Direction::Forward
            } else {
                Direction::Both
            })
        }
    }
}

/// Whether a road runs under something: a tunnel or a covered road.
pub fn is_covered(way: &Way) -> bool {
    matches!(
        way.tag("tunnel"),
        Some("yes" | "building_passage" | "avalanche_protector")
    ) || way.tag("covered") == Some("yes")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn way(tags: &[(&str, &str)]) -> Way {
        Way {
            id: 1,
            refs: vec![1, 2],
            tags: tags
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
        }
    }

    #[test]
    fn oneway_tags_roundabouts_and_motorways_set_the_direction() {
        for (tags, expected) in [
            (vec![("highway", "residential")], Ok(Direction::Both)),
            (
                vec![("highway", "residential"), ("oneway", "yes")],
                Ok(Direction::Forward),
            ),
            (
                vec![("highway", "primary"), ("oneway", "-1")],
                Ok(Direction::Backward),
            ),
            (
                vec![("highway", "tertiary"), ("junction", "roundabout")],
                Ok(Direction::Forward),
            ),
            (
                vec![
                    ("highway", "tertiary"),
                    ("junction", "roundabout"),
                    ("oneway", "no"),
                ],
                Ok(Direction::Both),
            ),
            (vec![("highway", "motorway")], Ok(Direction::Forward)),
            (
                vec![("highway", "motorway_link"), ("oneway", "no")],
                Ok(Direction::Both),
            ),
            (
                vec![("highway", "secondary"), ("oneway", "reversible")],
                Err(NotDriven::Shape),
            ),
        ] {
            assert_eq!(drivable(&way(&tags)), expected, "{tags:?}");
        }
    }

    #[test]
    fn classes_and_access_a_private_car_may_not_use_are_not_driven() {
        for (tags, expected) in [
            (vec![("highway", "footway")], Err(NotDriven::Class)),
            (vec![("highway", "track")], Err(NotDriven::Class)),
            (
                vec![("highway", "service"), ("service", "parking_aisle")],
                Err(NotDriven::Class),
            ),
            (
                vec![("highway", "service"), ("service", "alley")],
                Ok(Direction::Both),
            ),
            (
                vec![("highway", "residential"), ("access", "private")],
                Err(NotDriven::Access),
            ),
            // The most specific tag decides.
            (
                vec![
                    ("highway", "residential"),
                    ("access", "no"),
                    ("motor_vehicle", "yes"),
                ],
                Ok(Direction::Both),
            ),
            (
                vec![("highway", "unclassified"), ("motorcar", "no")],
                Err(NotDriven::Access),
            ),
            (
                vec![("highway", "pedestrian"), ("area", "yes")],
                Err(NotDriven::Class),
            ),
            (
                vec![("highway", "residential"), ("area", "yes")],
                Err(NotDriven::Shape),
            ),
        ] {
            assert_eq!(drivable(&way(&tags)), expected, "{tags:?}");
        }
        assert!(is_covered(&way(&[("tunnel", "yes")])));
        assert!(is_covered(&way(&[("covered", "yes")])));
        assert!(!is_covered(&way(&[("tunnel", "no")])));
    }
}
