//! PNG plots of one run: the scene, and the estimation error over time with occluded and
//! out-of-view spans shaded (like the paper's per-run figure).

use std::path::Path;

use plotters::prelude::*;

use super::ReportError;
use crate::sim::run::Snapshot;
use infotrack_core::metrics::StepRecord;
use infotrack_core::world::World;

fn plot_err(path: &Path, e: impl std::fmt::Display) -> ReportError {
    ReportError::Plot {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn ensure_parent(path: &Path) -> Result<(), ReportError> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|source| ReportError::Io {
            path: parent.to_path_buf(),
            source,
        })?;
    }
    Ok(())
}

const SNAPSHOT_COLOURS: [RGBColor; 3] = [
    RGBColor(0, 150, 0),
    RGBColor(230, 140, 0),
    RGBColor(150, 0, 200),
];

/// The scene: workspace, roads, occlusions, target and agent tracks, particles at a few
/// instants.
fn draw_scene(
    path: &Path,
    title: &str,
    world: &World,
    steps: &[StepRecord],
    snapshots: &[Snapshot],
) -> Result<(), ReportError> {
    ensure_parent(path)?;
    let ws = world.workspace_enu;
    let aspect = ws.height_m() / ws.width_m();
    let w = 900u32;
    let h = ((w as f64 * aspect) as u32 + 80).clamp(300, 1400);
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(ws.x_min_m..ws.x_max_m, ws.y_min_m..ws.y_max_m)
        .map_err(|e| plot_err(path, e))?;
    chart
        .configure_mesh()
        .x_desc("x east (m)")
        .y_desc("y north (m)")
        .draw()
        .map_err(|e| plot_err(path, e))?;
    draw_world(&mut chart, world).map_err(|e| plot_err(path, e))?;
    for (k, snap) in snapshots.iter().enumerate() {
        let colour = SNAPSHOT_COLOURS[k % SNAPSHOT_COLOURS.len()];
        chart
            .draw_series(
                snap.particles_enu
                    .iter()
                    .filter(|p| ws.contains(p))
                    .map(|p| Circle::new((p.x, p.y), 1, colour.mix(0.5).filled())),
            )
            .map_err(|e| plot_err(path, e))?
            .label(format!("particles t = {:.0} s", snap.t_s))
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, colour.filled()));
    }
    chart
        .draw_series(LineSeries::new(
            steps.iter().map(|s| (s.target_enu.x, s.target_enu.y)),
            BLUE.stroke_width(2),
        ))
        .map_err(|e| plot_err(path, e))?
        .label("target")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(
            steps.iter().map(|s| (s.agent_enu.x, s.agent_enu.y)),
            RED.stroke_width(1),
        ))
        .map_err(|e| plot_err(path, e))?
        .label("agent")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(1)));
    let estimate = RGBColor(0, 160, 160);
    chart
        .draw_series(LineSeries::new(
            steps.iter().map(|s| (s.estimate_enu.x, s.estimate_enu.y)),
            estimate.stroke_width(1),
        ))
        .map_err(|e| plot_err(path, e))?
        .label("estimate")
        .legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 20, y)], estimate.stroke_width(1))
        });
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| plot_err(path, e))?;
    root.present().map_err(|e| plot_err(path, e))
}

type SceneChart<'a> = ChartContext<
    'a,
    BitMapBackend<'a>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Occlusions (grey areas) and roads (dark lines), each with one legend entry.
fn draw_world(chart: &mut SceneChart<'_>, world: &World) -> Result<(), String> {
    let occlusion = BLACK.mix(0.25);
    let polygons = world.occlusions.iter().map(|occ| {
        let pts: Vec<(f64, f64)> = occ.vertices().iter().map(|v| (v.x, v.y)).collect();
        Polygon::new(pts, occlusion.filled())
    });
    let drawn = chart.draw_series(polygons).map_err(|e| e.to_string())?;
    if !world.occlusions.is_empty() {
        drawn.label("occlusion").legend(move |(x, y)| {
            Rectangle::new([(x, y - 5), (x + 20, y + 5)], occlusion.filled())
        });
    }
    let road = BLACK.mix(0.5);
    let edges = world.road.edges_enu();
    let drawn = chart
        .draw_series(
            edges
                .iter()
                .map(|(a, b)| PathElement::new(vec![(a.x, a.y), (b.x, b.y)], road.stroke_width(2))),
        )
        .map_err(|e| e.to_string())?;
    if !edges.is_empty() {
        drawn.label("road").legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 20, y)], road.stroke_width(2))
        });
    }
    Ok(())
}

/// Estimation error over time; red spans: target occluded; grey spans: target outside the
/// footprint.
fn draw_estimation_error(
    path: &Path,
    title: &str,
    steps: &[StepRecord],
) -> Result<(), ReportError> {
    ensure_parent(path)?;
    let t_max = steps.last().map(|s| s.t_s).unwrap_or(1.0);
    let e_max = steps
        .iter()
        .map(|s| s.estimation_error_m())
        .fold(0.0, f64::max)
        .max(1e-3)
        * 1.1;
    let root = BitMapBackend::new(path, (1000, 400)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(path, e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_max, 0.0..e_max)
        .map_err(|e| plot_err(path, e))?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("estimation error (m)")
        .draw()
        .map_err(|e| plot_err(path, e))?;
    let dt = if steps.len() > 1 {
        steps[1].t_s - steps[0].t_s
    } else {
        1.0
    };
    chart
        .draw_series(
            steps
                .iter()
                .filter(|s| !s.target_in_footprint && !s.target_occluded)
                .map(|s| {
                    Rectangle::new(
                        [(s.t_s - dt, 0.0), (s.t_s, e_max)],
                        BLACK.mix(0.12).filled(),
                    )
                }),
        )
        .map_err(|e| plot_err(path, e))?
        .label("out of view")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 15, y + 5)], BLACK.mix(0.12).filled()));
    chart
        .draw_series(
            steps.iter().filter(|s| s.target_occluded).map(|s| {
                Rectangle::new([(s.t_s - dt, 0.0), (s.t_s, e_max)], RED.mix(0.2).filled())
            }),
        )
        .map_err(|e| plot_err(path, e))?
        .label("occluded")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 15, y + 5)], RED.mix(0.2).filled()));
    chart
        .draw_series(LineSeries::new(
            steps.iter().map(|s| (s.t_s, s.estimation_error_m())),
            BLUE.stroke_width(2),
        ))
        .map_err(|e| plot_err(path, e))?
        .label("estimation error")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| plot_err(path, e))?;
    root.present().map_err(|e| plot_err(path, e))
}

/// The scene: workspace, roads, occlusions, target and agent tracks, particles at a few
/// instants; written whole or not at all.
pub fn scene(
    path: &Path,
    title: &str,
    world: &World,
    steps: &[StepRecord],
    snapshots: &[Snapshot],
) -> Result<(), ReportError> {
    super::whole_file(path, |tmp| draw_scene(tmp, title, world, steps, snapshots))
}

/// The estimation error over time; written whole or not at all.
pub fn estimation_error(path: &Path, title: &str, steps: &[StepRecord]) -> Result<(), ReportError> {
    super::whole_file(path, |tmp| draw_estimation_error(tmp, title, steps))
}
