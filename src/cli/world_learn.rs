//! `infotrack world learn`: turn probabilities from recorded tracks of an area's traffic,
//! written into a copy of its world.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde_json::{json, Value};

use infotrack::config::Config;
use infotrack::recorded_track::{load, TrackFrame};
use infotrack::report::write_file;
use infotrack::world::road::{RoadNetwork, TurnCounts};

/// A world or config file larger than this is refused, bytes.
const MAX_WORLD_BYTES: u64 = 256 << 20;

/// `infotrack world learn`.
#[derive(clap::Args)]
pub struct LearnArgs {
    /// The world's config; its roads must come from `[world] geojson`.
    #[arg(long)]
    pub config: PathBuf,
    /// A recorded track of the area's traffic (CSV, GPX or SUMO FCD, as `target.trajectory`
    /// reads them); repeat for more. Not the tracks the world will be judged on.
    #[arg(long = "track", required = true)]
    pub tracks: Vec<PathBuf>,
    /// In an FCD file with several vehicles, which one (default: the config's
    /// `target.trajectory_vehicle`, else the file's only vehicle).
    #[arg(long)]
    pub vehicle: Option<String>,
    /// How many turns the map's own probabilities count as at each node: the weight of
    /// what the map says against what the tracks show.
    #[arg(long, default_value_t = 2.0)]
    pub pseudo_turns: f64,
    /// A sample farther than this from the road it is put on is not matched, m.
    #[arg(long, default_value_t = 15.0)]
    pub max_off_road_m: f64,
    /// The learned world's name: NAME.geojson and NAME.toml are written beside the config,
    /// so that the config's relative paths keep their meaning.
    #[arg(long)]
    pub name: String,
}

/// Runs `infotrack world learn`.
pub fn learn(a: LearnArgs) -> Result<()> {
    check_args(&a)?;
    let cfg = Config::load(&a.config)?;
    let (world, geojson_path) = world_file(&cfg, &a.config)?;
    let road = RoadNetwork::from_config(&cfg.road)?;
    let tracks = read_tracks(&cfg, &a)?;
    let (counts, _) = road.count_turns(&tracks, a.max_off_road_m);
    if counts.turns() == 0 {
        bail!(
            "no turn was matched in {} tracks: are they of this world's area (within {} m of \
             its roads)?",
            tracks.len(),
            a.max_off_road_m
        );
    }
    let learned = road.learned_probabilities(&counts, a.pseudo_turns);
    let dir = a.config.parent().unwrap_or(Path::new("."));
    let out_geojson = dir.join(format!("{}.geojson", a.name));
    let out_config = dir.join(format!("{}.toml", a.name));
    let origin = cfg
        .world
        .as_ref()
        .map(|w| w.origin)
        .context("[world] origin")?;
    let text = learned_world(&world, &road, &learned, &origin);
    write_file(&out_geojson, format!("{text:#}\n").as_bytes())?;
    write_file(&out_config, learned_config(&a, &geojson_path)?.as_bytes())?;
    Config::load(&out_config)
        .with_context(|| format!("the written config {}", out_config.display()))?;
    println!("{}", summary(&counts, &road, tracks.len()));
    println!(
        "wrote {} and {}; fly it with `infotrack sim --config {}`",
        out_geojson.display(),
        out_config.display(),
        out_config.display()
    );
    Ok(())
}

fn check_args(a: &LearnArgs) -> Result<()> {
    if !(a.pseudo_turns.is_finite() && a.pseudo_turns > 0.0) {
        bail!(
            "--pseudo-turns must be a positive number, not {}",
            a.pseudo_turns
        );
    }
    if !(a.max_off_road_m.is_finite() && a.max_off_road_m > 0.0) {
        bail!(
            "--max-off-road-m must be a positive number of metres, not {}",
            a.max_off_road_m
        );
    }
    let ok = !a.name.is_empty()
        && a.name
            .chars()
            .all(|c| c.is_alphanumeric() || "-_.".contains(c));
    if !ok || a.name.starts_with('.') {
        bail!(
            "--name {:?}: letters, digits, '-', '_' and '.' only",
            a.name
        );
    }
    Ok(())
}

/// The config's GeoJSON world, parsed, and its path as the config names it.
fn world_file(cfg: &Config, config: &Path) -> Result<(Value, PathBuf)> {
    let Some(named) = cfg.world.as_ref().and_then(|w| w.geojson.clone()) else {
        bail!(
            "{}: world learn needs a config whose roads come from [world] geojson",
            config.display()
        );
    };
    let path = config.parent().unwrap_or(Path::new(".")).join(&named);
    let text = infotrack::bounded_file::read_text(&path, MAX_WORLD_BYTES)
        .with_context(|| format!("[world] geojson {}", path.display()))?;
    let world = serde_json::from_str(&text)
        .with_context(|| format!("[world] geojson {}", path.display()))?;
    Ok((world, named))
}

fn read_tracks(cfg: &Config, a: &LearnArgs) -> Result<Vec<Vec<(f64, infotrack::frames::Enu2)>>> {
    let frame = TrackFrame {
        origin: cfg.world.as_ref().map(|w| &w.origin),
        workspace: &cfg.workspace_enu,
        vehicle: a
            .vehicle
            .as_deref()
            .or(cfg.target.trajectory_vehicle.as_deref()),
    };
    a.tracks
        .iter()
        .map(|f| {
            load(f, &frame)
                .map(|t| t.samples)
                .with_context(|| format!("--track {}", f.display()))
        })
        .collect()
}

/// The world with its roads replaced by one one-way road per directed edge, each with its
/// learned probability (the graph is the same: the same positions meet at the same nodes),
/// and every other feature as it was.
fn learned_world(
    world: &Value,
    road: &RoadNetwork,
    learned: &[Vec<f64>],
    origin: &infotrack::geodesy::GeodeticWgs84,
) -> Value {
    let lonlat = |p: &infotrack::frames::Enu2| {
        let g = origin.offset_by_enu([p.x, p.y, 0.0]);
        json!([g.lon_deg, g.lat_deg])
    };
    let features = world["features"].as_array().cloned().unwrap_or_default();
    let mut out: Vec<Value> = features
        .into_iter()
        .filter(|f| f["properties"]["infotrack"] != "road")
        .collect();
    for (u, node) in road.nodes.iter().enumerate() {
        for (j, &(v, _)) in node.next.iter().enumerate() {
            let mut props = json!({"infotrack": "road", "oneway": true, "p": learned[u][j]});
            if u == road.start && j == 0 {
                props["start"] = json!(true);
            }
            let line = [
                lonlat(&node.position_enu),
                lonlat(&road.nodes[v].position_enu),
            ];
            out.push(json!({"type": "Feature", "properties": props,
                "geometry": {"type": "LineString", "coordinates": line}}));
        }
    }
    let mut w = world.clone();
    w["features"] = Value::Array(out);
    w
}

/// The config as it was, but for its name and its GeoJSON world.
fn learned_config(a: &LearnArgs, was: &Path) -> Result<String> {
    let text = infotrack::bounded_file::read_text(&a.config, MAX_WORLD_BYTES)
        .with_context(|| format!("{}", a.config.display()))?;
    let mut t: toml::Table = text
        .parse()
        .with_context(|| format!("{}", a.config.display()))?;
    t.insert("name".into(), a.name.clone().into());
    let world = t
        .get_mut("world")
        .and_then(|w| w.as_table_mut())
        .context("[world]")?;
    world.insert("geojson".into(), format!("{}.geojson", a.name).into());
    let tracks: Vec<String> = a.tracks.iter().map(|t| t.display().to_string()).collect();
    Ok(format!(
        "# Made by `infotrack world learn` from {} ({}): its turn probabilities learned from\n\
         # {} recorded tracks: {}.\n\n{}",
        a.config.display(),
        was.display(),
        tracks.len(),
        tracks.join(", "),
        toml::to_string(&t).context("the config as TOML")?
    ))
}

fn summary(c: &TurnCounts, road: &RoadNetwork, tracks: usize) -> String {
    let choices = road.nodes.iter().filter(|n| n.next.len() > 1).count();
    let seen_choices = road
        .nodes
        .iter()
        .zip(&c.counts)
        .filter(|(n, k)| n.next.len() > 1 && k.iter().any(|&x| x > 0))
        .count();
    format!(
        "{tracks} tracks: {} samples matched, {} off every road, {} breaks; {} turns counted \
         ({} of them turning back) at {} nodes, {seen_choices} of the {choices} nodes with a \
         choice of exits",
        c.matched_samples,
        c.off_road_samples,
        c.breaks,
        c.turns(),
        c.turn_backs,
        c.nodes_seen()
    )
}
