//! The `world` subcommand: worlds from OpenStreetMap extracts.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use infotrack::config::Config;
use infotrack::report::write_file;
use infotrack_osm::{Bbox, ImportedWorld};

/// What `infotrack world` does.
#[derive(clap::Args)]
pub struct WorldArgs {
    /// The action.
    #[command(subcommand)]
    pub action: WorldAction,
}

/// The actions of `infotrack world`.
#[derive(clap::Subcommand)]
pub enum WorldAction {
    /// Make a world from an OpenStreetMap extract: the roads a car may drive within the
    /// box (kept to their largest strongly connected part), tunnels, covered roads and woods
    /// over roads as occlusions, the box as the geofence; writes NAME.geojson and a config
    /// NAME.toml beside it with the field settings of config/outdoor.toml.
    Import(ImportArgs),
    /// Learn a world's turn probabilities from recorded tracks of its traffic: each track is
    /// matched to the roads, the turns it takes counted, and the counts update the map's
    /// probabilities; writes NAME.geojson and NAME.toml beside the config.
    Learn(super::world_learn::LearnArgs),
}

/// `infotrack world import`.
#[derive(clap::Args)]
pub struct ImportArgs {
    /// The extract: `.osm.pbf`, or `.osm` XML.
    #[arg(long)]
    pub osm: PathBuf,
    /// The box, degrees (WGS84): lon_min,lat_min,lon_max,lat_max.
    #[arg(long, allow_hyphen_values = true)]
    pub bbox: String,
    /// The folder NAME.geojson and NAME.toml are written into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// The world's name; default: the extract's file name without its extensions.
    #[arg(long)]
    pub name: Option<String>,
}

/// The flight settings an imported world's config starts from.
const TEMPLATE: &str = include_str!("../../config/outdoor.toml");

/// Runs `infotrack world`.
pub fn world(a: WorldArgs) -> Result<()> {
    match a.action {
        WorldAction::Import(i) => import(i),
        WorldAction::Learn(l) => super::world_learn::learn(l),
    }
}

fn import(a: ImportArgs) -> Result<()> {
    let bbox = Bbox::parse(&a.bbox)?;
    let name = a.name.clone().unwrap_or_else(|| stem(&a.osm));
    let data = infotrack_osm::read::read(&a.osm, &bbox)?;
    let world = infotrack_osm::import(&data, &bbox)?;
    let geojson = a.out.join(format!("{name}.geojson"));
    let config = a.out.join(format!("{name}.toml"));
    write_file(&geojson, format!("{:#}\n", world.geojson).as_bytes())?;
    write_file(&config, config_text(&world, &name, &a, &bbox)?.as_bytes())?;
    Config::load(&config).with_context(|| format!("the written config {}", config.display()))?;
    println!("{}", world.summary);
    println!(
        "wrote {} and {}; fly it with `infotrack sim --config {}`",
        geojson.display(),
        config.display(),
        config.display()
    );
    Ok(())
}

/// `helsinki` of `data/helsinki.osm.pbf`.
fn stem(path: &Path) -> String {
    let file = path.file_name().and_then(|f| f.to_str()).unwrap_or("world");
    file.split('.').next().unwrap_or("world").to_string()
}

/// The config beside the world: the template's flight settings, the world's own place,
/// start, geofence and lawnmower sweep.
fn config_text(world: &ImportedWorld, name: &str, a: &ImportArgs, bbox: &Bbox) -> Result<String> {
    let mut t: toml::Table = toml::from_str(TEMPLATE).context("the embedded template")?;
    for key in ["road", "workspace_enu", "occlusions", "acquisition"] {
        t.remove(key);
    }
    t.insert("name".into(), name.into());
    if let Some(m) = t.get_mut("motion").and_then(|m| m.as_table_mut()) {
        // The template's learned model was trained for another world: the daemon predicts
        // with constant velocity until one is trained for this one.
        m.remove("dmmn_model");
    }
    let daemon = t
        .entry("daemon")
        .or_insert_with(|| toml::Table::new().into())
        .as_table_mut()
        .context("[daemon]")?;
    daemon.insert("motion".into(), "cv".into());
    let [x0, x1, y0, y1] = world.workspace_enu;
    let agent = t["agent"].as_table_mut().context("[agent]")?;
    agent.insert("start_enu_m".into(), pair(world.start_enu));
    let lawn = t["guidance"]["lawn"]
        .as_table_mut()
        .context("[guidance.lawn]")?;
    let legs: Vec<toml::Value> = (0..)
        .map(|k| x0 + 30.0 + 60.0 * k as f64)
        .take_while(|x| *x <= x1 - 30.0)
        .map(|x| toml::Value::from((x * 10.0).round() / 10.0))
        .collect();
    lawn.insert("legs_x_m".into(), legs.into());
    lawn.insert("y_min_m".into(), ((y0 + 20.0).ceil()).into());
    lawn.insert("y_max_m".into(), ((y1 - 20.0).floor()).into());
    let o = &world.origin;
    let place: toml::Table = format!(
        "origin = {{ lat_deg = {}, lon_deg = {}, alt_m = {} }}\ngeojson = \"{name}.geojson\"",
        o.lat_deg, o.lon_deg, o.alt_m
    )
    .parse()
    .context("[world]")?;
    t.insert("world".into(), place.into());
    Ok(format!(
        "# Made by `infotrack world import` from {} within {},{},{},{}: the roads, occlusions,\n\
         # geofence and cue are in {name}.geojson; the flight settings are config/outdoor.toml's.\n\
         # Set [world] origin.alt_m to the ground's height above the ellipsoid before a real flight.\n\
         # Map data (c) OpenStreetMap contributors, ODbL 1.0: https://www.openstreetmap.org/copyright\n\n{}",
        a.osm.display(),
        bbox.lon_min,
        bbox.lat_min,
        bbox.lon_max,
        bbox.lat_max,
        toml::to_string(&t).context("the config as TOML")?
    ))
}

fn pair(p: [f64; 2]) -> toml::Value {
    toml::Value::Array(vec![
        ((p[0] * 10.0).round() / 10.0).into(),
        ((p[1] * 10.0).round() / 10.0).into(),
    ])
}
