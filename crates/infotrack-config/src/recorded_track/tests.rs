use super::*;

const ORIGIN: GeodeticWgs84 = GeodeticWgs84 {
    lat_deg: 47.397742,
    lon_deg: 8.545594,
    alt_m: 488.0,
};

const FENCE: BoundsEnu = BoundsEnu {
    x_min_m: -500.0,
    x_max_m: 500.0,
    y_min_m: -500.0,
    y_max_m: 500.0,
};

fn frame() -> TrackFrame<'static> {
    TrackFrame {
        origin: Some(&ORIGIN),
        workspace: &FENCE,
        vehicle: None,
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// `[lon, lat]` of world ENU (east, north).
fn lonlat(e: f64, n: f64) -> (f64, f64) {
    let g = ORIGIN.offset_by_enu([e, n, 0.0]);
    (g.lon_deg, g.lat_deg)
}

#[test]
fn csv_in_metres_and_degrees_read_as_the_same_track() {
    let dir = tempfile::tempdir().unwrap();
    let xy = write(
        dir.path(),
        "a.csv",
        "t_s,x_m,y_m\n10,0,0\n12,20,0\n14,20,10\n",
    );
    let (a, b, c) = (lonlat(0.0, 0.0), lonlat(20.0, 0.0), lonlat(20.0, 10.0));
    let geo = write(
        dir.path(),
        "b.csv",
        &format!(
            "t_s,lon_deg,lat_deg\n10,{},{}\n12,{},{}\n14,{},{}\n",
            a.0, a.1, b.0, b.1, c.0, c.1
        ),
    );
    let t1 = load(&xy, &frame()).unwrap();
    let t2 = load(&geo, &frame()).unwrap();
    assert_eq!(t1.duration_s(), 4.0);
    for t in [0.0, 1.0, 2.5, 4.0, 9.0] {
        let (p1, v1) = t1.at(t);
        let (p2, _) = t2.at(t);
        assert!((p1 - p2).norm() < 1e-6, "{t}: {p1} vs {p2}");
        if t == 1.0 {
            assert!(
                (p1 - Enu2::new(10.0, 0.0)).norm() < 1e-9
                    && (v1 - Enu2::new(10.0, 0.0)).norm() < 1e-9
            );
        }
    }
    assert_eq!(t1.at(9.0).1, Enu2::zeros(), "held at its end");
}

#[test]
fn gpx_and_sumo_fcd_read_with_their_times() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (lonlat(0.0, 0.0), lonlat(0.0, 30.0));
    let gpx = format!(
        r#"<?xml version="1.0"?><gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>
<trkpt lat="{}" lon="{}"><time>2024-05-01T12:00:00Z</time></trkpt>
<trkpt lat="{}" lon="{}"><time>2024-05-01T12:00:03Z</time></trkpt>
</trkseg></trk></gpx>"#,
        a.1, a.0, b.1, b.0
    );
    let t = load(&write(dir.path(), "a.gpx", &gpx), &frame()).unwrap();
    assert_eq!(t.samples.len(), 2);
    assert!((t.duration_s() - 3.0).abs() < 1e-9);
    assert!((t.at(1.5).0 - Enu2::new(0.0, 15.0)).norm() < 1e-3);
    let fcd = format!(
        r#"<fcd-export>
<timestep time="0.00"><vehicle id="bg" x="{ax}" y="{ay}"/><vehicle id="ego" x="{ax}" y="{ay}"/></timestep>
<timestep time="1.00"><vehicle id="ego" x="{bx}" y="{by}"/></timestep>
</fcd-export>"#,
        ax = a.0,
        ay = a.1,
        bx = b.0,
        by = b.1
    );
    let file = write(dir.path(), "fcd.xml", &fcd);
    let err = load(&file, &frame()).unwrap_err().to_string();
    assert!(
        err.contains("2 vehicles") && err.contains("trajectory_vehicle"),
        "{err}"
    );
    let ego = TrackFrame {
        vehicle: Some("ego"),
        ..frame()
    };
    let t = load(&file, &ego).unwrap();
    assert_eq!(t.samples.len(), 2);
    assert!((t.at(1.0).0 - Enu2::new(0.0, 30.0)).norm() < 1e-3);
}

#[test]
fn tracks_that_cannot_be_are_refused_naming_the_file_and_row() {
    let dir = tempfile::tempdir().unwrap();
    let case = |name: &str, text: &str| {
        load(&write(dir.path(), name, text), &frame())
            .unwrap_err()
            .to_string()
    };
    let e = case("back.csv", "t_s,x_m,y_m\n0,0,0\n2,5,0\n1,6,0\n");
    assert!(
        e.contains("back.csv, line 4") && e.contains("does not follow"),
        "{e}"
    );
    let e = case("out.csv", "t_s,x_m,y_m\n0,0,0\n100,900,0\n");
    assert!(
        e.contains("out.csv, line 3") && e.contains("outside the workspace"),
        "{e}"
    );
    let e = case("fast.csv", "t_s,x_m,y_m\n0,0,0\n1,300,0\n");
    assert!(
        e.contains("fast.csv, line 3") && e.contains("faster than any car"),
        "{e}"
    );
    let e = case("head.csv", "time,x,y\n0,0,0\n");
    assert!(
        e.contains("head.csv, line 1") && e.contains("t_s,x_m,y_m"),
        "{e}"
    );
    let e = case("nan.csv", "t_s,x_m,y_m\n0,0,0\n1,nan,0\n");
    assert!(e.contains("nan.csv, line 3"), "{e}");
    let e = case("one.csv", "t_s,x_m,y_m\n0,0,0\n");
    assert!(e.contains("at least two"), "{e}");
    let e = case(
        "no-time.gpx",
        r#"<gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg><trkpt lat="47.39" lon="8.54"/></trkseg></trk></gpx>"#,
    );
    assert!(
        e.contains("no-time.gpx, track point 1") && e.contains("no <time>"),
        "{e}"
    );
    let e = case("a.kml", "");
    assert!(e.contains("unknown track type"), "{e}");
    let nowhere = TrackFrame {
        origin: None,
        ..frame()
    };
    let e = load(
        &write(
            dir.path(),
            "geo.csv",
            "t_s,lon_deg,lat_deg\n0,8.5,47.3\n1,8.5,47.3\n",
        ),
        &nowhere,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("[world] origin"), "{e}");
}
