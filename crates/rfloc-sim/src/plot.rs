//! Plots of a simulated run, drawn with `plotters` into SVG text.
//!
//! - [`trial_svg`]: one trial (`plot.svg`). A map panel in metres at equal scale on both axes
//!   (ticks, grid, a scale bar): the world's walls and obstacles, its HF/UHF tags, beacons and
//!   emitter, the true and the estimated path with heading arrows, the stops (true pose), the
//!   readings (sensor → landmark), estimated landmarks, start, goal and waypoints; a legend
//!   beside it. Under it, the errors over time: position error (m, left axis) and absolute
//!   heading error (°, right axis) of every estimate against the truth interpolated at its time.
//! - [`summary_svg`]: one scenario (`summary.svg`). Per-trial RMSE and maximum position error
//!   (bars, failed trials marked) and the distribution (empirical CDF) of every estimate's
//!   position error over all trials.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use rfloc_pose::angle_diff;

use crate::geometry::Point;
use crate::metrics::{interpolate, TimedPose};
use crate::recorder::Reading;
use crate::world::World;

/// Width of a trial plot, pixels.
const WIDTH: u32 = 960;
/// Width of the map's legend column, pixels.
const LEGEND_W: u32 = 210;
/// Map chart: margin and label areas (the plotting area is what is left), pixels.
const MAP_MARGIN: u32 = 12;
const MAP_X_LABELS: u32 = 42;
const MAP_Y_LABELS: u32 = 62;
/// Height of the error-over-time panel, pixels.
const ERROR_H: u32 = 270;
/// Smallest and largest height of the map's plotting area, pixels.
const MAP_MIN_H: f64 = 260.0;
const MAP_MAX_H: f64 = 640.0;
/// At most this many heading arrows per path.
const MAX_ARROWS: usize = 24;

const FONT: &str = "sans-serif";
const TRUE_C: RGBColor = RGBColor(32, 96, 208);
const EST_C: RGBColor = RGBColor(224, 112, 0);
const WALL_C: RGBColor = RGBColor(0, 0, 0);
const OBSTACLE_C: RGBColor = RGBColor(200, 200, 200);
const HF_C: RGBColor = RGBColor(128, 64, 192);
const UHF_C: RGBColor = RGBColor(208, 64, 64);
const BEACON_C: RGBColor = RGBColor(48, 160, 48);
const EMITTER_C: RGBColor = RGBColor(240, 160, 0);
const READ_C: RGBColor = RGBColor(150, 100, 200);
const STOP_C: RGBColor = RGBColor(10, 40, 120);
const GOAL_C: RGBColor = RGBColor(220, 30, 30);
const START_C: RGBColor = RGBColor(20, 150, 60);
const GRID_C: RGBColor = RGBColor(232, 232, 232);

/// Everything a trial plot shows.
#[derive(Debug, Clone, Copy)]
pub struct TrialPlot<'a> {
    pub title: &'a str,
    pub world: &'a World,
    pub truth: &'a [TimedPose],
    pub estimate: &'a [TimedPose],
    /// Where the robot stood still on purpose (true pose).
    pub stops: &'a [TimedPose],
    pub readings: &'a [Reading],
    /// Labelled estimated landmarks (beacons, the emitter).
    pub marks: &'a [(String, Point)],
    pub waypoints: &'a [Point],
    /// Goal and its tolerance.
    pub goal: Option<(Point, f64)>,
    /// Label of the time axis, with its unit (`time (s)`).
    pub time_label: &'a str,
}

/// One trial of a scenario summary.
#[derive(Debug, Clone, Copy)]
pub struct SummaryTrial<'a> {
    pub trial: usize,
    pub success: bool,
    pub truth: &'a [TimedPose],
    pub estimate: &'a [TimedPose],
}

/// A drawing error (plotters' errors carry the backend's error type; only the text is kept).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("drawing the plot: {0}")]
pub struct PlotError(pub String);

fn err<E: std::fmt::Debug>(e: E) -> PlotError {
    PlotError(format!("{e:?}"))
}

/// Position error (m) and absolute heading error (°) of every estimate at its time.
#[must_use]
pub fn errors_over_time(truth: &[TimedPose], estimate: &[TimedPose]) -> Vec<(f64, f64, f64)> {
    estimate
        .iter()
        .filter_map(|e| {
            let t = interpolate(truth, e.t)?;
            Some((
                e.t,
                t.distance(&e.pose),
                angle_diff(e.pose.theta, t.theta).abs().to_degrees(),
            ))
        })
        .collect()
}

/// A "nice" step (1, 2 or 5 × 10ⁿ) near `span / 5`.
fn nice_step(span: f64) -> f64 {
    let raw = (span / 5.0).max(1e-6);
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    let n = if f < 1.5 {
        1.0
    } else if f < 3.5 {
        2.0
    } else if f < 7.5 {
        5.0
    } else {
        10.0
    };
    n * mag
}

/// Decimals that tick labels over `span` need (ticks are about `span / 10` apart).
fn decimals(span: f64) -> usize {
    let step = (span / 10.0).abs().max(1e-9);
    usize::try_from((-step.log10().floor()).max(0.0) as i64)
        .unwrap_or(0)
        .min(6)
}

/// A tick label of `v` with `d` decimals (no "-0.0").
fn tick(v: f64, d: usize) -> String {
    let text = format!("{v:.d$}");
    if text.starts_with('-') && text.trim_start_matches(['-', '0', '.']).is_empty() {
        text.trim_start_matches('-').to_string()
    } else {
        text
    }
}

/// A length in metres as the scale bar writes it.
fn metres(v: f64) -> String {
    if v >= 1.0 {
        format!("{v} m")
    } else {
        format!("{} cm", (v * 100.0).round())
    }
}

/// Data bounds of the map: the world's area and everything drawn, padded by 4 %.
fn map_bounds(p: &TrialPlot<'_>) -> (f64, f64, f64, f64) {
    let w = p.world;
    let (mut x0, mut y0, mut x1, mut y1) = (w.area_min.x, w.area_min.y, w.area_max.x, w.area_max.y);
    let mut add = |x: f64, y: f64| {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    };
    for tp in p.truth.iter().chain(p.estimate) {
        add(tp.pose.x, tp.pose.y);
    }
    for (_, m) in p.marks {
        add(m.x, m.y);
    }
    for r in p.readings {
        add(r.sensor.x, r.sensor.y);
    }
    for wp in p.waypoints {
        add(wp.x, wp.y);
    }
    if let Some((g, _)) = p.goal {
        add(g.x, g.y);
    }
    let span = (x1 - x0).max(y1 - y0).max(0.1);
    let pad = 0.04 * span;
    (x0 - pad, y0 - pad, x1 + pad, y1 + pad)
}

/// Equal-scale ranges and the map panel's pixel height: the plotting area is
/// `plot_w × plot_h` pixels and both ranges have the same metres per pixel.
fn equal_scale(bounds: (f64, f64, f64, f64), plot_w: f64) -> ((f64, f64), (f64, f64), f64) {
    let (x0, y0, x1, y1) = bounds;
    let (sx, sy) = ((x1 - x0).max(1e-3), (y1 - y0).max(1e-3));
    let plot_h = (plot_w * sy / sx).clamp(MAP_MIN_H, MAP_MAX_H).round();
    // Metres per pixel: the larger of the two needs.
    let mpp = (sx / plot_w).max(sy / plot_h);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let (hx, hy) = (0.5 * mpp * plot_w, 0.5 * mpp * plot_h);
    ((cx - hx, cx + hx), (cy - hy, cy + hy), plot_h)
}

/// Indices of at most `max` evenly spaced items of `n`.
fn spaced(n: usize, max: usize) -> impl Iterator<Item = usize> {
    let step = n.div_ceil(max.max(1)).max(1);
    (0..n).step_by(step)
}

/// An arrow from `(x, y)` along `theta`, `len` metres long.
fn arrow(x: f64, y: f64, theta: f64, len: f64) -> Vec<Vec<(f64, f64)>> {
    let (c, s) = (theta.cos(), theta.sin());
    let tip = (x + len * c, y + len * s);
    let head = 0.35 * len;
    let wing = |a: f64| {
        (
            tip.0 - head * (theta + a).cos(),
            tip.1 - head * (theta + a).sin(),
        )
    };
    vec![vec![(x, y), tip], vec![wing(0.45), tip, wing(-0.45)]]
}

/// A legend entry: how to draw its sample and its text.
#[derive(Debug, Clone, Copy)]
enum Sample {
    Line(RGBColor, u32),
    Dashed(RGBColor),
    Arrow(RGBColor),
    Dot(RGBColor, bool),
    Cross(RGBColor),
    Diamond(RGBColor),
    Triangle(RGBColor),
    Fill(RGBColor),
}

fn draw_legend(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    title: &str,
    entries: &[(Sample, String)],
) -> Result<(), PlotError> {
    let text = |s: &str, x: i32, y: i32, size: u32| -> Result<(), PlotError> {
        area.draw_text(
            s,
            &TextStyle::from((FONT, size))
                .color(&BLACK)
                .pos(Pos::new(HPos::Left, VPos::Center)),
            (x, y),
        )
        .map_err(err)
    };
    text(title, 8, 24, 15)?;
    for (i, (sample, label)) in entries.iter().enumerate() {
        let y = 50 + 20 * i32::try_from(i).unwrap_or(0);
        let (x0, x1) = (10, 40);
        match *sample {
            Sample::Line(c, w) => area
                .draw(&PathElement::new(vec![(x0, y), (x1, y)], c.stroke_width(w)))
                .map_err(err)?,
            Sample::Dashed(c) => {
                for k in 0..3 {
                    let a = x0 + 11 * k;
                    area.draw(&PathElement::new(
                        vec![(a, y), (a + 7, y)],
                        c.stroke_width(2),
                    ))
                    .map_err(err)?;
                }
            }
            Sample::Arrow(c) => {
                area.draw(&PathElement::new(vec![(x0, y), (x1, y)], c.stroke_width(2)))
                    .map_err(err)?;
                area.draw(&PathElement::new(
                    vec![(x1 - 7, y - 5), (x1, y), (x1 - 7, y + 5)],
                    c.stroke_width(2),
                ))
                .map_err(err)?;
            }
            Sample::Dot(c, filled) => area
                .draw(&Circle::new(
                    (25, y),
                    5,
                    if filled {
                        c.filled()
                    } else {
                        c.stroke_width(2)
                    },
                ))
                .map_err(err)?,
            Sample::Cross(c) => area
                .draw(&Cross::new((25, y), 5, c.stroke_width(2)))
                .map_err(err)?,
            Sample::Diamond(c) => area
                .draw(&Polygon::new(
                    vec![(25, y - 6), (31, y), (25, y + 6), (19, y)],
                    c.filled(),
                ))
                .map_err(err)?,
            Sample::Triangle(c) => area
                .draw(&TriangleMarker::new((25, y), 6, c.filled()))
                .map_err(err)?,
            Sample::Fill(c) => area
                .draw(&Rectangle::new([(x0, y - 6), (x1, y + 6)], c.filled()))
                .map_err(err)?,
        }
        text(label, 50, y, 13)?;
    }
    Ok(())
}

/// Renders one trial as an SVG document.
///
/// # Errors
/// [`PlotError`] when plotters fails to draw (it does not for finite data).
pub fn trial_svg(p: &TrialPlot<'_>) -> Result<String, PlotError> {
    let map_w = WIDTH - LEGEND_W;
    let plot_w = f64::from(map_w - 2 * MAP_MARGIN - MAP_Y_LABELS);
    let ((x0, x1), (y0, y1), plot_h) = equal_scale(map_bounds(p), plot_w);
    let title_h = 34u32;
    // Pixel height of the map panel: its plotting area plus margins and the x labels.
    let map_h = plot_h as u32 + 2 * MAP_MARGIN + MAP_X_LABELS;
    let height = title_h + map_h + ERROR_H;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, height)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(p.title, (FONT, 18)).map_err(err)?;
        let (top, bottom) = root.split_vertically(map_h);
        let (map_area, legend_area) = top.split_horizontally(map_w);
        let legend = draw_map(&map_area, p, (x0, x1), (y0, y1))?;
        draw_legend(&legend_area, "map", &legend)?;
        let (err_area, err_legend_area) = bottom.split_horizontally(map_w);
        let legend = draw_errors(&err_area, p)?;
        draw_legend(&err_legend_area, "errors", &legend)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

fn draw_map(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    p: &TrialPlot<'_>,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
) -> Result<Vec<(Sample, String)>, PlotError> {
    let mut legend: Vec<(Sample, String)> = Vec::new();
    let mut chart = ChartBuilder::on(area)
        .margin(MAP_MARGIN)
        .x_label_area_size(MAP_X_LABELS)
        .y_label_area_size(MAP_Y_LABELS)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .axis_desc_style((FONT, 14))
        .label_style((FONT, 12))
        .light_line_style(GRID_C)
        .bold_line_style(RGBColor(205, 205, 205))
        .max_light_lines(2)
        .x_label_formatter(&|v| tick(*v, decimals(x1 - x0)))
        .y_label_formatter(&|v| tick(*v, decimals(y1 - y0)))
        .draw()
        .map_err(err)?;
    let span = (x1 - x0).max(y1 - y0);
    let w = p.world;

    // The world.
    if !w.obstacles.is_empty() {
        chart
            .draw_series(w.obstacles.iter().map(|o| {
                Polygon::new(
                    o.vertices.iter().map(|v| (v.x, v.y)).collect::<Vec<_>>(),
                    OBSTACLE_C.filled(),
                )
            }))
            .map_err(err)?;
        legend.push((Sample::Fill(OBSTACLE_C), "obstacle".into()));
    }
    if !w.walls.is_empty() {
        chart
            .draw_series(w.walls.iter().map(|s| {
                PathElement::new(vec![(s.a.x, s.a.y), (s.b.x, s.b.y)], WALL_C.stroke_width(2))
            }))
            .map_err(err)?;
        legend.push((Sample::Line(WALL_C, 2), "wall".into()));
    }
    if !w.hf_tags.is_empty() {
        chart
            .draw_series(
                w.hf_tags
                    .iter()
                    .map(|t| Circle::new((t.position.x, t.position.y), 3, HF_C.stroke_width(1))),
            )
            .map_err(err)?;
        legend.push((Sample::Dot(HF_C, false), "HF floor tag".into()));
    }
    if !w.uhf_tags.is_empty() {
        chart
            .draw_series(
                w.uhf_tags
                    .iter()
                    .map(|t| Circle::new((t.position.x, t.position.y), 2, UHF_C.stroke_width(1))),
            )
            .map_err(err)?;
        legend.push((Sample::Dot(UHF_C, false), "UHF tag".into()));
    }
    if !w.beacons.is_empty() {
        chart
            .draw_series(w.beacons.iter().map(|b| {
                EmptyElement::at((b.position.x, b.position.y))
                    + Circle::new((0, 0), 6, BEACON_C.filled())
                    + Text::new(b.ni.clone(), (8, -16), (FONT, 12))
            }))
            .map_err(err)?;
        legend.push((Sample::Dot(BEACON_C, true), "beacon (true)".into()));
    }
    if let Some(e) = &w.emitter {
        chart
            .draw_series(std::iter::once(
                EmptyElement::at((e.position.x, e.position.y))
                    + Circle::new((0, 0), 7, EMITTER_C.filled())
                    + Circle::new((0, 0), 7, BLACK.stroke_width(1))
                    + Text::new("emitter", (9, -18), (FONT, 12)),
            ))
            .map_err(err)?;
        legend.push((Sample::Dot(EMITTER_C, true), "emitter (true)".into()));
    }

    // Readings: a line from the sensor to the landmark read, the landmarks read labelled with
    // their count.
    if !p.readings.is_empty() {
        chart
            .draw_series(p.readings.iter().map(|r| {
                PathElement::new(
                    vec![(r.sensor.x, r.sensor.y), (r.landmark.x, r.landmark.y)],
                    READ_C.mix(0.35).stroke_width(1),
                )
            }))
            .map_err(err)?;
        let mut read: Vec<(String, Point, usize)> = Vec::new();
        for r in p.readings {
            match read.iter_mut().find(|(l, _, _)| *l == r.label) {
                Some(e) => e.2 += 1,
                None => read.push((r.label.clone(), r.landmark, 1)),
            }
        }
        chart
            .draw_series(read.iter().map(|(label, at, n)| {
                EmptyElement::at((at.x, at.y))
                    + Circle::new((0, 0), 5, READ_C.filled())
                    + Text::new(format!("{label} ×{n}"), (7, 4), (FONT, 11))
            }))
            .map_err(err)?;
        legend.push((
            Sample::Line(READ_C, 1),
            "reading (sensor → landmark)".into(),
        ));
        legend.push((Sample::Dot(READ_C, true), "landmark read (× count)".into()));
    }

    // Paths and heading arrows.
    let len = 0.045 * span;
    if !p.truth.is_empty() {
        chart
            .draw_series(LineSeries::new(
                p.truth.iter().map(|t| (t.pose.x, t.pose.y)),
                TRUE_C.stroke_width(2),
            ))
            .map_err(err)?;
        legend.push((Sample::Line(TRUE_C, 2), "true path".into()));
    }
    if !p.estimate.is_empty() {
        chart
            .draw_series(DashedLineSeries::new(
                p.estimate.iter().map(|t| (t.pose.x, t.pose.y)),
                6,
                4,
                EST_C.stroke_width(2),
            ))
            .map_err(err)?;
        legend.push((Sample::Dashed(EST_C), "estimated path".into()));
        // Estimated heading at (some of) the estimates, with the true pose of the same time.
        let picks: Vec<usize> = spaced(p.estimate.len(), MAX_ARROWS).collect();
        // A trial with a single answer (an initial pose) shows it larger.
        let len = if p.estimate.len() <= 3 {
            2.0 * len
        } else {
            len
        };
        let mut true_arrows = Vec::new();
        let mut est_arrows = Vec::new();
        for i in picks {
            let Some(e) = p.estimate.get(i) else { continue };
            est_arrows.extend(arrow(e.pose.x, e.pose.y, e.pose.theta, len));
            if let Some(t) = interpolate(p.truth, e.t) {
                true_arrows.extend(arrow(t.x, t.y, t.theta, len));
            }
        }
        chart
            .draw_series(
                true_arrows
                    .into_iter()
                    .map(|a| PathElement::new(a, TRUE_C.stroke_width(2))),
            )
            .map_err(err)?;
        chart
            .draw_series(
                est_arrows
                    .into_iter()
                    .map(|a| PathElement::new(a, EST_C.stroke_width(2))),
            )
            .map_err(err)?;
        legend.push((Sample::Arrow(TRUE_C), "true pose and heading".into()));
        legend.push((Sample::Arrow(EST_C), "estimated pose and heading".into()));
    }
    if !p.stops.is_empty() {
        let mut arrows = Vec::new();
        for s in p.stops {
            arrows.extend(arrow(s.pose.x, s.pose.y, s.pose.theta, 1.6 * len));
        }
        chart
            .draw_series(
                arrows
                    .into_iter()
                    .map(|a| PathElement::new(a, STOP_C.stroke_width(1))),
            )
            .map_err(err)?;
        chart
            .draw_series(
                p.stops
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| {
                        // Every stop numbered up to 12, then about 12 of them and the last.
                        let every = p.stops.len().div_ceil(12).max(1);
                        k % every == 0 || k + 1 == p.stops.len()
                    })
                    .map(|(k, s)| {
                        let d = 1.9 * len;
                        Text::new(
                            format!("{}", k + 1),
                            (
                                s.pose.x + d * s.pose.theta.cos(),
                                s.pose.y + d * s.pose.theta.sin(),
                            ),
                            TextStyle::from((FONT, 11))
                                .color(&STOP_C)
                                .pos(Pos::new(HPos::Center, VPos::Center)),
                        )
                    }),
            )
            .map_err(err)?;
        legend.push((
            Sample::Arrow(STOP_C),
            format!("stop 1–{} (true pose)", p.stops.len()),
        ));
    }

    // Estimated landmarks.
    if !p.marks.is_empty() {
        chart
            .draw_series(p.marks.iter().map(|(label, at)| {
                EmptyElement::at((at.x, at.y))
                    + Cross::new((0, 0), 6, EST_C.stroke_width(2))
                    + Text::new(label.clone(), (8, 4), (FONT, 11))
            }))
            .map_err(err)?;
        legend.push((Sample::Cross(EST_C), "landmark estimate".into()));
    }

    // Start, waypoints, goal.
    if let Some(s) = p.truth.first() {
        chart
            .draw_series(std::iter::once(TriangleMarker::new(
                (s.pose.x, s.pose.y),
                7,
                START_C.filled(),
            )))
            .map_err(err)?;
        legend.push((Sample::Triangle(START_C), "start".into()));
    }
    if !p.waypoints.is_empty() {
        chart
            .draw_series(p.waypoints.iter().map(|wp| {
                EmptyElement::at((wp.x, wp.y))
                    + Polygon::new(vec![(0, -7), (7, 0), (0, 7), (-7, 0)], GOAL_C.filled())
            }))
            .map_err(err)?;
        legend.push((Sample::Diamond(GOAL_C), "waypoint".into()));
    }
    if let Some((g, tol)) = p.goal {
        let ring: Vec<(f64, f64)> = (0..=48)
            .map(|k| {
                let a = f64::from(k) * std::f64::consts::TAU / 48.0;
                (g.x + tol * a.cos(), g.y + tol * a.sin())
            })
            .collect();
        chart
            .draw_series(std::iter::once(PathElement::new(
                ring,
                GOAL_C.stroke_width(1),
            )))
            .map_err(err)?;
        chart
            .draw_series(std::iter::once(Cross::new(
                (g.x, g.y),
                7,
                GOAL_C.stroke_width(3),
            )))
            .map_err(err)?;
        legend.push((Sample::Cross(GOAL_C), format!("goal (± {tol} m)")));
    }

    // Scale bar, bottom left, inside the margin around the world; its length written beside it.
    let bar = nice_step(x1 - x0);
    let (bx, by) = (x0 + 0.02 * (x1 - x0), y0 + 0.02 * (y1 - y0));
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(bx, by), (bx + bar, by)],
            BLACK.stroke_width(4),
        )))
        .map_err(err)?;
    chart
        .draw_series(std::iter::once(Text::new(
            format!("scale: {}", metres(bar)),
            (bx + bar + 0.01 * (x1 - x0), by),
            TextStyle::from((FONT, 12)).pos(Pos::new(HPos::Left, VPos::Center)),
        )))
        .map_err(err)?;
    Ok(legend)
}

fn draw_errors(
    area: &DrawingArea<SVGBackend<'_>, Shift>,
    p: &TrialPlot<'_>,
) -> Result<Vec<(Sample, String)>, PlotError> {
    let errors = errors_over_time(p.truth, p.estimate);
    let times = p.truth.iter().chain(p.estimate).map(|t| t.t);
    let (t0, t1) = times.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), t| {
        (a.min(t), b.max(t))
    });
    let (t0, t1) = if t0.is_finite() && t1 > t0 {
        (t0, t1)
    } else {
        (0.0, 1.0)
    };
    let max_d = errors.iter().map(|e| e.1).fold(0.0, f64::max);
    let max_h = errors.iter().map(|e| e.2).fold(0.0, f64::max);
    let top_d = if max_d > 0.0 { 1.1 * max_d } else { 0.01 };
    let top_h = if max_h > 0.0 { 1.1 * max_h } else { 1.0 };
    let mut chart = ChartBuilder::on(area)
        .margin(MAP_MARGIN)
        .x_label_area_size(MAP_X_LABELS)
        .y_label_area_size(MAP_Y_LABELS)
        .right_y_label_area_size(MAP_Y_LABELS)
        .build_cartesian_2d(t0..t1, 0.0..top_d)
        .map_err(err)?
        .set_secondary_coord(t0..t1, 0.0..top_h);
    chart
        .configure_mesh()
        .x_desc(p.time_label)
        .y_desc("position error (m)")
        .axis_desc_style((FONT, 14))
        .label_style((FONT, 12))
        .light_line_style(GRID_C)
        .bold_line_style(RGBColor(205, 205, 205))
        .max_light_lines(2)
        .x_label_formatter(&|v| tick(*v, decimals(t1 - t0)))
        .y_label_formatter(&|v| tick(*v, decimals(top_d)))
        .draw()
        .map_err(err)?;
    chart
        .configure_secondary_axes()
        .y_label_formatter(&|v| tick(*v, decimals(top_h)))
        .y_desc("heading error (°)")
        .axis_desc_style((FONT, 14))
        .label_style((FONT, 12))
        .draw()
        .map_err(err)?;
    let mut legend = Vec::new();
    if errors.is_empty() {
        chart
            .draw_series(std::iter::once(Text::new(
                "no estimate",
                (t0 + 0.4 * (t1 - t0), 0.5 * top_d),
                (FONT, 16),
            )))
            .map_err(err)?;
        return Ok(legend);
    }
    chart
        .draw_series(LineSeries::new(
            errors.iter().map(|e| (e.0, e.1)),
            EST_C.stroke_width(2),
        ))
        .map_err(err)?;
    chart
        .draw_secondary_series(LineSeries::new(
            errors.iter().map(|e| (e.0, e.2)),
            TRUE_C.stroke_width(1),
        ))
        .map_err(err)?;
    if errors.len() <= 60 {
        chart
            .draw_series(
                errors
                    .iter()
                    .map(|e| Circle::new((e.0, e.1), 4, EST_C.filled())),
            )
            .map_err(err)?;
        chart
            .draw_secondary_series(
                errors
                    .iter()
                    .map(|e| Cross::new((e.0, e.2), 4, TRUE_C.stroke_width(2))),
            )
            .map_err(err)?;
    }
    for s in p.stops {
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(s.t, 0.0), (s.t, top_d)],
                STOP_C.mix(0.25).stroke_width(1),
            )))
            .map_err(err)?;
    }
    legend.push((Sample::Line(EST_C, 2), "position error (m, left)".into()));
    legend.push((Sample::Line(TRUE_C, 1), "heading error (°, right)".into()));
    if !p.stops.is_empty() {
        legend.push((Sample::Line(STOP_C, 1), "stop".into()));
    }
    Ok(legend)
}

/// Renders a scenario's summary as an SVG document: per-trial RMSE and maximum position error,
/// and the empirical CDF of every estimate's position error.
///
/// # Errors
/// [`PlotError`] when plotters fails to draw.
pub fn summary_svg(title: &str, trials: &[SummaryTrial<'_>]) -> Result<String, PlotError> {
    let per_trial: Vec<(usize, bool, Vec<f64>)> = trials
        .iter()
        .map(|t| {
            let d = errors_over_time(t.truth, t.estimate)
                .into_iter()
                .map(|e| e.1)
                .collect();
            (t.trial, t.success, d)
        })
        .collect();
    let stats: Vec<(usize, bool, f64, f64)> = per_trial
        .iter()
        .map(|(k, ok, d)| {
            let n = d.len().max(1) as f64;
            let rmse = (d.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
            let max = d.iter().copied().fold(0.0, f64::max);
            (*k, *ok, rmse, max)
        })
        .collect();
    let mut all: Vec<f64> = per_trial.iter().flat_map(|t| t.2.iter().copied()).collect();
    all.sort_by(f64::total_cmp);
    let top = stats.iter().map(|s| s.3).fold(0.0, f64::max);
    let top = if top > 0.0 { 1.15 * top } else { 0.01 };

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, 420)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let root = root.titled(title, (FONT, 18)).map_err(err)?;
        let (left, right) = root.split_horizontally(WIDTH / 2);

        // Per-trial bars.
        let n = stats.len().max(1) as f64;
        let mut chart = ChartBuilder::on(&left)
            .margin(MAP_MARGIN)
            .x_label_area_size(MAP_X_LABELS)
            .y_label_area_size(MAP_Y_LABELS)
            .build_cartesian_2d(-0.5..n - 0.5, 0.0..top)
            .map_err(err)?;
        let labels: Vec<usize> = stats.iter().map(|s| s.0).collect();
        chart
            .configure_mesh()
            .x_desc("trial")
            .y_desc("position error (m)")
            .axis_desc_style((FONT, 14))
            .label_style((FONT, 12))
            .light_line_style(GRID_C)
            .x_labels(stats.len().clamp(1, 20))
            .x_label_formatter(&|v| {
                let i = v.round();
                if (v - i).abs() < 1e-6 && i >= 0.0 {
                    labels
                        .get(i as usize)
                        .map_or_else(String::new, ToString::to_string)
                } else {
                    String::new()
                }
            })
            .max_light_lines(2)
            .y_label_formatter(&|v| tick(*v, decimals(top)))
            .draw()
            .map_err(err)?;
        chart
            .draw_series(stats.iter().enumerate().map(|(i, s)| {
                let x = i as f64;
                Rectangle::new([(x - 0.38, 0.0), (x, s.2)], TRUE_C.filled())
            }))
            .map_err(err)?
            .label("RMSE")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], TRUE_C.filled()));
        chart
            .draw_series(stats.iter().enumerate().map(|(i, s)| {
                let x = i as f64;
                Rectangle::new([(x, 0.0), (x + 0.38, s.3)], EST_C.filled())
            }))
            .map_err(err)?
            .label("max")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], EST_C.filled()));
        chart
            .draw_series(
                stats
                    .iter()
                    .enumerate()
                    .filter(|(_, s)| !s.1)
                    .map(|(i, s)| {
                        Text::new(
                            "failed",
                            (i as f64, s.3.max(s.2) + 0.03 * top),
                            TextStyle::from((FONT, 12))
                                .color(&GOAL_C)
                                .pos(Pos::new(HPos::Center, VPos::Bottom)),
                        )
                    }),
            )
            .map_err(err)?;
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 12))
            .draw()
            .map_err(err)?;

        // Error distribution.
        let right_top = all.last().copied().filter(|v| *v > 0.0).unwrap_or(0.01) * 1.05;
        let mut cdf = ChartBuilder::on(&right)
            .margin(MAP_MARGIN)
            .x_label_area_size(MAP_X_LABELS)
            .y_label_area_size(MAP_Y_LABELS)
            .build_cartesian_2d(0.0..right_top, 0.0..1.0)
            .map_err(err)?;
        cdf.configure_mesh()
            .x_desc("position error (m)")
            .y_desc("fraction of estimates")
            .axis_desc_style((FONT, 14))
            .label_style((FONT, 12))
            .light_line_style(GRID_C)
            .max_light_lines(2)
            .x_label_formatter(&|v| tick(*v, decimals(right_top)))
            .draw()
            .map_err(err)?;
        let k = all.len() as f64;
        let mut steps = vec![(0.0, 0.0)];
        for (i, e) in all.iter().enumerate() {
            steps.push((*e, i as f64 / k));
            steps.push((*e, (i + 1) as f64 / k));
        }
        steps.push((right_top, if all.is_empty() { 0.0 } else { 1.0 }));
        cdf.draw_series(LineSeries::new(steps, TRUE_C.stroke_width(2)))
            .map_err(err)?
            .label(format!("all trials ({} estimates)", all.len()))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 14, y)], TRUE_C.stroke_width(2)));
        cdf.configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 12))
            .draw()
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfloc_pose::Pose2;
    use std::path::Path;

    fn world() -> World {
        World::from_toml_str(
            "[area]\nmin=[0.0,0.0]\nmax=[4.0,3.0]\n[[obstacles]]\npoints=[[1.0,1.0],[2.0,1.0],[2.0,2.0]]\n[[xbee_beacons]]\nx=1.0\ny=2.5\naddress=\"1\"\nni=\"beacon<1>\"\n",
            Path::new("w"),
        )
        .unwrap()
    }

    #[test]
    fn equal_scale_keeps_metres_per_pixel_on_both_axes() {
        for bounds in [
            (0.0, 0.0, 10.0, 1.0),
            (0.0, 0.0, 1.0, 10.0),
            (-3.0, -1.0, 5.0, 4.0),
        ] {
            let ((x0, x1), (y0, y1), h) = equal_scale(bounds, 600.0);
            assert!((MAP_MIN_H..=MAP_MAX_H).contains(&h));
            let (mx, my) = ((x1 - x0) / 600.0, (y1 - y0) / h);
            assert!(
                (mx - my).abs() < 1e-9 * mx.max(my),
                "{bounds:?}: {mx} vs {my}"
            );
            assert!(x0 <= bounds.0 && x1 >= bounds.2 && y0 <= bounds.1 && y1 >= bounds.3);
        }
        assert_eq!(nice_step(4.0), 1.0);
        assert_eq!(nice_step(0.9), 0.2);
        assert_eq!(metres(0.2), "20 cm");
        assert_eq!(
            (decimals(0.97), decimals(0.0011), decimals(15.0)),
            (2, 4, 0)
        );
        assert_eq!(
            (tick(-0.001, 2), tick(-0.5, 1), tick(2.0, 0)),
            ("0.00".into(), "-0.5".into(), "2".into())
        );
    }

    #[test]
    fn trial_plot_has_axes_units_legend_and_scale_bar() {
        let w = world();
        let truth: Vec<TimedPose> = (0..50)
            .map(|i| {
                TimedPose::new(
                    f64::from(i) * 0.1,
                    Pose2::new(0.5 + 0.05 * f64::from(i), 0.5, 0.0),
                )
            })
            .collect();
        let est: Vec<TimedPose> = truth
            .iter()
            .map(|t| TimedPose::new(t.t, Pose2::new(t.pose.x, t.pose.y + 0.1, 0.05)))
            .collect();
        let readings = vec![Reading {
            t: 1.0,
            label: "b1".into(),
            sensor: Point::new(1.0, 0.5),
            landmark: Point::new(1.0, 2.5),
        }];
        let stops = vec![TimedPose::new(2.0, Pose2::new(1.5, 0.5, 0.0))];
        let marks = vec![("b1".to_string(), Point::new(1.1, 2.4))];
        let s = trial_svg(&TrialPlot {
            title: "t & t",
            world: &w,
            truth: &truth,
            estimate: &est,
            stops: &stops,
            readings: &readings,
            marks: &marks,
            waypoints: &[Point::new(3.0, 0.5)],
            goal: Some((Point::new(3.5, 0.5), 0.3)),
            time_label: "time (s)",
        })
        .unwrap();
        assert!(
            s.starts_with("<svg") && s.trim_end().ends_with("</svg>"),
            "{s}"
        );
        for label in [
            "x (m)",
            "y (m)",
            "time (s)",
            "position error (m)",
            "heading error (°)",
            "true path",
            "estimated path",
            "true pose and heading",
            "estimated pose and heading",
            "stop 1–1 (true pose)",
            "b1 ×1",
            "beacon (true)",
            "beacon&lt;1&gt;",
            "landmark estimate",
            "obstacle",
            "waypoint",
            "goal (± 0.3 m)",
            "start",
            "scale: 1 m",
            "t &amp; t",
        ] {
            assert!(s.contains(label), "no {label:?} in the plot");
        }
        // Tick labels on the map's axes.
        let texts: Vec<&str> = s
            .split("<text")
            .skip(1)
            .filter_map(|t| t.split_once('>').and_then(|(_, r)| r.split_once("</text>")))
            .map(|(content, _)| content.trim())
            .collect();
        assert!(
            texts.contains(&"1.0") && texts.contains(&"2.0"),
            "no ticks: {texts:?}"
        );
    }

    #[test]
    fn a_plot_without_estimates_says_so() {
        let w = world();
        let truth = vec![TimedPose::new(0.0, Pose2::new(1.0, 1.0, 0.0))];
        let s = trial_svg(&TrialPlot {
            title: "x",
            world: &w,
            truth: &truth,
            estimate: &[],
            stops: &[],
            readings: &[],
            marks: &[],
            waypoints: &[],
            goal: None,
            time_label: "time (s)",
        })
        .unwrap();
        assert!(s.contains("no estimate"));
    }

    #[test]
    fn summary_plot_has_bars_cdf_and_units() {
        let truth: Vec<TimedPose> = (0..10)
            .map(|i| TimedPose::new(f64::from(i), Pose2::new(f64::from(i), 0.0, 0.0)))
            .collect();
        let est: Vec<TimedPose> = truth
            .iter()
            .map(|t| TimedPose::new(t.t, Pose2::new(t.pose.x, 0.2, 0.0)))
            .collect();
        let trials = [
            SummaryTrial {
                trial: 0,
                success: true,
                truth: &truth,
                estimate: &est,
            },
            SummaryTrial {
                trial: 1,
                success: false,
                truth: &truth,
                estimate: &est[..3],
            },
        ];
        let s = summary_svg("scenario", &trials).unwrap();
        for label in [
            "trial",
            "position error (m)",
            "fraction of estimates",
            "RMSE",
            "max",
            "failed",
            "all trials (13 estimates)",
        ] {
            assert!(s.contains(label), "no {label:?} in the summary");
        }
    }
}
