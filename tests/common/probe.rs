//! The response probe: one scripted flight that shows how a vehicle's position loop answers
//! a companion (takeoff, hover, a position step, a setpoint moving without and with
//! velocity feed-forward, the hold), recorded as a time series. Flown against the real
//! autopilots (SITL) it gives the fixtures under `tests/fixtures/sitl/`; flown against the
//! mock it gives what `tests/mock_calibration.rs` compares with them. The figures that
//! matter to tracking come out of [`Response::figures`].
#![allow(dead_code)]

use std::fmt::Write as _;
use std::time::{Duration, Instant};

use infotrack::autopilot::link::{LinkError, VehicleLink};
use infotrack::frames::{Enu2, PositionEnu};

/// Altitude of the manoeuvres: the lab's, m.
pub const ALTITUDE_M: f64 = 1.2;
/// The step's length, east, m.
pub const STEP_M: f64 = 1.0;
/// Speed of the moving setpoints (the lab target's cruise speed), m/s.
pub const RAMP_MPS: f64 = 0.3;
/// Seconds of each phase after the takeoff.
pub const HOVER_S: f64 = 8.0;
/// Seconds after the step.
pub const STEP_S: f64 = 8.0;
/// Seconds of each moving setpoint.
pub const RAMP_S: f64 = 10.0;
/// Seconds watched in the hold.
pub const HOLD_S: f64 = 10.0;
const SAMPLE: Duration = Duration::from_millis(20);

/// One sample: time since arming (s), phase, the setpoint and the reported position (world
/// ENU, m) and attitude (roll, pitch, rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Seconds since the vehicle armed.
    pub t_s: f64,
    /// Which manoeuvre.
    pub phase: Phase,
    /// The setpoint, world ENU, m (the hold: where the hold began).
    pub setpoint_enu_m: [f64; 3],
    /// The reported position, world ENU, m.
    pub position_enu_m: [f64; 3],
    /// Reported roll and pitch, rad.
    pub roll_pitch_rad: [f64; 2],
}

/// The manoeuvres, in flight order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// From arming to the takeoff altitude.
    Takeoff,
    /// Holding the setpoint over the start.
    Hover,
    /// After the setpoint jumped `STEP_M` east.
    Step,
    /// Following a setpoint moved west at `RAMP_MPS`, position only, updated at 10 Hz.
    RampPosition,
    /// The same with the velocity as feed-forward (position + velocity targets).
    RampFeedForward,
    /// The firmware's hold mode, entered by the link's `hold`.
    Hold,
}

impl Phase {
    const ALL: [Phase; 6] = [
        Phase::Takeoff,
        Phase::Hover,
        Phase::Step,
        Phase::RampPosition,
        Phase::RampFeedForward,
        Phase::Hold,
    ];

    /// Its name in the CSV.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Takeoff => "takeoff",
            Phase::Hover => "hover",
            Phase::Step => "step",
            Phase::RampPosition => "ramp_position",
            Phase::RampFeedForward => "ramp_feed_forward",
            Phase::Hold => "hold",
        }
    }

    fn parse(s: &str) -> Option<Phase> {
        Self::ALL.into_iter().find(|p| p.name() == s)
    }
}

/// A recorded probe flight.
#[derive(Debug, Clone, Default)]
pub struct Response {
    /// Samples every 20 ms.
    pub samples: Vec<Sample>,
}

/// What the probe measures, each comparable between vehicles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// Seconds from arming to 95 % of the takeoff altitude.
    pub takeoff_s: f64,
    /// RMS horizontal distance from the setpoint over the hover's last 5 s, m.
    pub hover_rms_m: f64,
    /// Seconds from the step to 90 % of it.
    pub step_rise_s: f64,
    /// How far past the step the vehicle went, m (0 when it never passed it).
    pub step_overshoot_m: f64,
    /// Mean horizontal distance from the moving setpoint over its last 5 s, position only, m.
    pub ramp_lag_m: f64,
    /// The same with feed-forward, m.
    pub feed_forward_lag_m: f64,
    /// RMS tilt (roll and pitch together) over the hover and the step, rad.
    pub tilt_rms_rad: f64,
    /// Altitude change over the hold, m (negative: it descended).
    pub hold_climb_m: f64,
    /// Horizontal drift over the hold's last 5 s, m.
    pub hold_drift_m: f64,
}

fn enu(p: [f64; 3]) -> PositionEnu {
    PositionEnu {
        x_east_m: p[0],
        y_north_m: p[1],
        z_up_m: p[2],
    }
}

/// Flies the probe on a link whose vehicle is connected, on the ground and sending
/// telemetry; `arm_timeout` covers a firmware that refuses to arm while it boots.
pub async fn fly(link: &VehicleLink, arm_timeout: Duration) -> Response {
    let mut rec = Recorder::default();
    let start = [0.0, 0.0, ALTITUDE_M];
    // Take off (the link's own sequence for the flavour), sampling all along. A takeoff the
    // vehicle abandons on the ground (its auto-disarm) is tried once more, as a pilot
    // would, and said on the log: the probe measures the flight, not the first arming.
    for attempt in 1..=2 {
        let takeoff = link.take_off(ALTITUDE_M, arm_timeout);
        tokio::pin!(takeoff);
        let mut tick = tokio::time::interval(SAMPLE);
        let done = loop {
            tokio::select! {
                r = &mut takeoff => break r,
                _ = tick.tick() => rec.sample(link, Phase::Takeoff, start),
            }
        };
        match done {
            Err(LinkError::TakeoffAbandoned { why }) if attempt == 1 => {
                eprintln!("probe: the first takeoff was abandoned ({why}); taking off again");
                rec.restart_takeoff();
            }
            r => {
                r.expect("takeoff");
                break;
            }
        }
    }
    link.set_setpoint(enu(start), 0.0).unwrap();
    rec.run(link, Phase::Hover, HOVER_S, |_| start).await;
    let stepped = [STEP_M, 0.0, ALTITUDE_M];
    link.set_setpoint(enu(stepped), 0.0).unwrap();
    rec.run(link, Phase::Step, STEP_S, |_| stepped).await;
    // West at RAMP_MPS, position only: the setpoint moved by the companion at 10 Hz.
    let ramp = |t: f64| [STEP_M - RAMP_MPS * t, 0.0, ALTITUDE_M];
    let began = Instant::now();
    let mut last_update = -1.0;
    while began.elapsed().as_secs_f64() < RAMP_S {
        let t = began.elapsed().as_secs_f64();
        if t - last_update >= 0.1 {
            link.set_setpoint(enu(ramp(t)), 0.0).unwrap();
            last_update = t;
        }
        rec.sample(link, Phase::RampPosition, ramp(t));
        tokio::time::sleep(SAMPLE).await;
    }
    // Back east with the velocity as feed-forward: one moving setpoint.
    let from = ramp(RAMP_S);
    let ff = |t: f64| [from[0] + RAMP_MPS * t, 0.0, ALTITUDE_M];
    link.set_moving_setpoint(enu(from), Enu2::new(RAMP_MPS, 0.0), 0.0)
        .unwrap();
    rec.run(link, Phase::RampFeedForward, RAMP_S, ff).await;
    let here = arr(link.position_enu().expect("a position"));
    link.hold().await.expect("hold");
    rec.run(link, Phase::Hold, HOLD_S, |_| here).await;
    rec.response
}

#[derive(Default)]
struct Recorder {
    armed_at: Option<Instant>,
    response: Response,
}

impl Recorder {
    /// Forgets an abandoned takeoff's samples: the takeoff's time counts from the arming
    /// that flew.
    fn restart_takeoff(&mut self) {
        self.armed_at = None;
        self.response.samples.clear();
    }

    fn sample(&mut self, link: &VehicleLink, phase: Phase, setpoint: [f64; 3]) {
        let state = link.state();
        if !state.armed && self.armed_at.is_none() {
            return;
        }
        let armed_at = *self.armed_at.get_or_insert_with(Instant::now);
        let (Some(p), Some((_, att))) = (link.position_enu(), state.attitude) else {
            return;
        };
        self.response.samples.push(Sample {
            t_s: armed_at.elapsed().as_secs_f64(),
            phase,
            setpoint_enu_m: setpoint,
            position_enu_m: arr(p),
            roll_pitch_rad: [att[0] as f64, att[1] as f64],
        });
    }

    async fn run(
        &mut self,
        link: &VehicleLink,
        phase: Phase,
        seconds: f64,
        setpoint: impl Fn(f64) -> [f64; 3],
    ) {
        let began = Instant::now();
        while began.elapsed().as_secs_f64() < seconds {
            self.sample(link, phase, setpoint(began.elapsed().as_secs_f64()));
            tokio::time::sleep(SAMPLE).await;
        }
    }
}

fn arr(p: PositionEnu) -> [f64; 3] {
    [p.x_east_m, p.y_north_m, p.z_up_m]
}

fn horizontal(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    assert!(n > 0, "no samples to average");
    s / n as f64
}

impl Response {
    fn phase(&self, p: Phase) -> Vec<Sample> {
        self.samples
            .iter()
            .copied()
            .filter(|s| s.phase == p)
            .collect()
    }

    /// The phase's samples from `from_s` seconds after it began.
    fn tail(&self, p: Phase, from_s: f64) -> Vec<Sample> {
        let all = self.phase(p);
        let t0 = all.first().expect("the phase was recorded").t_s;
        all.into_iter().filter(|s| s.t_s - t0 >= from_s).collect()
    }

    /// The figures of this flight.
    pub fn figures(&self) -> Figures {
        let climb = self.phase(Phase::Takeoff);
        let t0 = self.samples[0].t_s;
        let up = self
            .samples
            .iter()
            .find(|s| s.position_enu_m[2] >= 0.95 * ALTITUDE_M)
            .expect("reached the takeoff altitude");
        assert!(!climb.is_empty());
        let hover = self.tail(Phase::Hover, HOVER_S - 5.0);
        let step = self.phase(Phase::Step);
        let step_t0 = step[0].t_s;
        let start_x = step[0].position_enu_m[0];
        let rise = step
            .iter()
            .find(|s| s.position_enu_m[0] - start_x >= 0.9 * (STEP_M - start_x))
            .map(|s| s.t_s - step_t0)
            .unwrap_or(f64::INFINITY);
        let overshoot = step
            .iter()
            .map(|s| s.position_enu_m[0] - STEP_M)
            .fold(0.0, f64::max);
        let tilt = mean(
            self.phase(Phase::Hover)
                .iter()
                .chain(step.iter())
                .map(|s| s.roll_pitch_rad[0].powi(2) + s.roll_pitch_rad[1].powi(2)),
        )
        .sqrt();
        let lag = |p| {
            mean(
                self.tail(p, RAMP_S - 5.0)
                    .iter()
                    .map(|s| horizontal(s.position_enu_m, s.setpoint_enu_m)),
            )
        };
        let hold = self.phase(Phase::Hold);
        let hold_tail = self.tail(Phase::Hold, HOLD_S - 5.0);
        Figures {
            takeoff_s: up.t_s - t0,
            hover_rms_m: mean(
                hover
                    .iter()
                    .map(|s| horizontal(s.position_enu_m, s.setpoint_enu_m).powi(2)),
            )
            .sqrt(),
            step_rise_s: rise,
            step_overshoot_m: overshoot,
            ramp_lag_m: lag(Phase::RampPosition),
            feed_forward_lag_m: lag(Phase::RampFeedForward),
            tilt_rms_rad: tilt,
            hold_climb_m: hold.last().unwrap().position_enu_m[2] - hold[0].position_enu_m[2],
            hold_drift_m: horizontal(
                hold_tail.last().unwrap().position_enu_m,
                hold_tail[0].position_enu_m,
            ),
        }
    }

    /// As CSV, one sample per line.
    pub fn to_csv(&self) -> String {
        let mut out = String::from(
            "t_s,phase,setpoint_e_m,setpoint_n_m,setpoint_u_m,e_m,n_m,u_m,roll_rad,pitch_rad\n",
        );
        for s in &self.samples {
            let (sp, p) = (s.setpoint_enu_m, s.position_enu_m);
            writeln!(
                out,
                "{:.3},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.5},{:.5}",
                s.t_s,
                s.phase.name(),
                sp[0],
                sp[1],
                sp[2],
                p[0],
                p[1],
                p[2],
                s.roll_pitch_rad[0],
                s.roll_pitch_rad[1]
            )
            .unwrap();
        }
        out
    }

    /// Reads [`Self::to_csv`]'s format; a bad line is named.
    pub fn from_csv(text: &str) -> Result<Response, String> {
        let mut samples = Vec::new();
        for (i, line) in text.lines().enumerate().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            let bad = || format!("line {}: {line:?} is not a probe sample", i + 1);
            if f.len() != 10 {
                return Err(bad());
            }
            let n = |k: usize| f[k].parse::<f64>().map_err(|_| bad());
            samples.push(Sample {
                t_s: n(0)?,
                phase: Phase::parse(f[1]).ok_or_else(bad)?,
                setpoint_enu_m: [n(2)?, n(3)?, n(4)?],
                position_enu_m: [n(5)?, n(6)?, n(7)?],
                roll_pitch_rad: [n(8)?, n(9)?],
            });
        }
        Ok(Response { samples })
    }
}

/// Asserts that a vehicle's figures lie within the range a reference vehicle showed over
/// its recorded flights, widened by a margin: 35 % of the reference's mean (times and
/// distances; 50 % for the tilt) or an absolute floor (0.5 s, 0.05 m, 0.01 rad; 0.3 m for
/// the hold's climb), whichever is larger. One flight of a real autopilot wanders, so the
/// range of several is the reference, not one of them.
pub fn assert_within(name: &str, a: &Figures, reference: &str, flights: &[Figures]) {
    assert_within_floors(name, a, reference, flights, &[]);
}

/// [`assert_within`] with larger absolute floors for the named figures (`floors`: figure,
/// metres or seconds), where a reference's recordings are known to understate its spread.
pub fn assert_within_floors(
    name: &str,
    a: &Figures,
    reference: &str,
    flights: &[Figures],
    floors: &[(&str, f64)],
) {
    if let Err(why) = within_floors(name, a, reference, flights, floors) {
        panic!("{why}");
    }
}

/// What [`assert_within_floors`] checks, saying what is out of range instead of failing.
pub fn within_floors(
    name: &str,
    a: &Figures,
    reference: &str,
    flights: &[Figures],
    floors: &[(&str, f64)],
) -> Result<(), String> {
    assert!(!flights.is_empty(), "no recorded flights of {reference}");
    type Get = fn(&Figures) -> f64;
    let checks: [(&str, Get, f64, f64); 9] = [
        ("takeoff_s", |f| f.takeoff_s, 0.35, 0.5),
        ("hover_rms_m", |f| f.hover_rms_m, 0.35, 0.05),
        ("step_rise_s", |f| f.step_rise_s, 0.35, 0.5),
        ("step_overshoot_m", |f| f.step_overshoot_m, 0.35, 0.05),
        ("ramp_lag_m", |f| f.ramp_lag_m, 0.35, 0.05),
        ("feed_forward_lag_m", |f| f.feed_forward_lag_m, 0.35, 0.05),
        ("tilt_rms_rad", |f| f.tilt_rms_rad, 0.5, 0.01),
        ("hold_climb_m", |f| f.hold_climb_m, 0.0, 0.3),
        ("hold_drift_m", |f| f.hold_drift_m, 0.35, 0.05),
    ];
    let mut off = Vec::new();
    for (key, get, rel, abs) in checks {
        let values: Vec<f64> = flights.iter().map(get).collect();
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let mean = values.iter().sum::<f64>() / values.len() as f64;
        let floor = floors
            .iter()
            .find(|(k, _)| *k == key)
            .map_or(abs, |(_, f)| f.max(abs));
        let margin = floor.max(rel * mean.abs());
        let x = get(a);
        if !(x >= lo - margin && x <= hi + margin) {
            off.push(format!(
                "{key}: {name} {x:.3}, {reference} {lo:.3}..{hi:.3} (+- {margin:.3})"
            ));
        }
    }
    if off.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{name} answers the probe unlike {reference}:\n{}\n{name}: {a:?}\n{reference}: {flights:?}",
            off.join("\n")
        ))
    }
}

/// The figures of the recorded flights `tests/fixtures/sitl/NAME-K.csv` (K = 1, 2, ...).
pub fn recorded(name: &str) -> Vec<Figures> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/sitl");
    let mut out = Vec::new();
    for k in 1.. {
        let p = dir.join(format!("{name}-{k}.csv"));
        let Ok(text) = std::fs::read_to_string(&p) else {
            break;
        };
        let flight = Response::from_csv(&text).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        out.push(flight.figures());
    }
    assert!(
        !out.is_empty(),
        "no recordings {}/{name}-1.csv",
        dir.display()
    );
    out
}

/// Each figure's median over `flights` (a figure that never came, infinite, counts as the
/// largest).
pub fn median(flights: &[Figures]) -> Figures {
    let m = |get: fn(&Figures) -> f64| {
        let mut v: Vec<f64> = flights.iter().map(get).collect();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    Figures {
        takeoff_s: m(|f| f.takeoff_s),
        hover_rms_m: m(|f| f.hover_rms_m),
        step_rise_s: m(|f| f.step_rise_s),
        step_overshoot_m: m(|f| f.step_overshoot_m),
        ramp_lag_m: m(|f| f.ramp_lag_m),
        feed_forward_lag_m: m(|f| f.feed_forward_lag_m),
        tilt_rms_rad: m(|f| f.tilt_rms_rad),
        hold_climb_m: m(|f| f.hold_climb_m),
        hold_drift_m: m(|f| f.hold_drift_m),
    }
}
