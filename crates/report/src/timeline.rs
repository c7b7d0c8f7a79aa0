//! Timing figures: the timeline of one exposure as the timing model predicts it (wheel segment
//! with spoke mixing, pattern shown, exposure window, zoomed on the exposure's start and end,
//! with the weight matrix and warnings), and the trigger chain as a run's devices logged it.

use plotters::prelude::*;
use specmux_core::error::Result;
use specmux_twin::timing::TimingConfig;
use specmux_twin::timing::{weights, Schedule, TimingWeights};
use std::path::Path;

const WIDTH: u32 = 1500;
const PANELS_HEIGHT: u32 = 560;
const LINE: u32 = 22;

/// Segment/pattern colour i: the filter's colour chip when `chips` has one, else a hue wheel.
fn colour(chips: &[[u8; 3]], i: usize, n: usize) -> RGBColor {
    match chips.get(i) {
        Some(&[r, g, b]) => RGBColor(r, g, b),
        None => {
            let (r, g, b) = HSLColor(i as f64 / n as f64, 0.65, 0.55).to_rgba().rgb();
            RGBColor(r, g, b)
        }
    }
}

/// Write the timeline PNG of one exposure of `cfg` to `path` (atomically); segment i and its
/// pattern are drawn in `chips[i]`, the colour of filter i (`plot::Colorimetry::chip`).
pub fn timeline_png(cfg: &TimingConfig, chips: &[[u8; 3]], path: &Path) -> Result<()> {
    let tw = weights(cfg)?;
    let s = Schedule::new(cfg);
    let text_lines = 3 + s.n + tw.warnings.len();
    let height = PANELS_HEIGHT + LINE * text_lines as u32 + 20;
    crate::plot::render_png(path, (WIDTH, height), |root| {
        let (top, bottom) = root.split_vertically(PANELS_HEIGHT);
        let (t0, t) = (cfg.camera.start_s, cfg.camera.exposure_s);
        let p = s.period;
        let windows = if t <= 3.0 * p {
            vec![("the whole exposure", t0 - 0.5 * p, t0 + t + 0.5 * p)]
        } else {
            vec![
                (
                    "exposure start: the first turns",
                    t0 - 0.5 * p,
                    t0 + 2.5 * p,
                ),
                (
                    "exposure end: the last turns",
                    t0 + t - 2.0 * p,
                    t0 + t + 0.5 * p,
                ),
            ]
        };
        let panels = top.split_evenly((1, windows.len()));
        for (area, (title, a, b)) in panels.iter().zip(windows) {
            draw_panel(area, &s, chips, title, a, b, (t0, t0 + t)).map_err(|e| e.to_string())?;
        }
        draw_text(&bottom, cfg, &tw).map_err(|e| e.to_string())
    })
}

type Area<'a> = crate::plot::Canvas<'a>;

/// One zoom window: lanes (top to bottom) wheel segment fractions, pattern shown, exposure.
fn draw_panel(
    area: &Area,
    s: &Schedule,
    chips: &[[u8; 3]],
    title: &str,
    a: f64,
    b: f64,
    (exp_a, exp_b): (f64, f64),
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    let ms = 1e3;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        // Room for the last tick's label, which is centred on the right edge.
        .margin_right(28)
        .x_label_area_size(40)
        .y_label_area_size(10)
        .build_cartesian_2d(a * ms..b * ms, 0.0..3.4)?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .disable_y_axis()
        .x_desc("time after the index pulse (ms)")
        .x_label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 16))
        .draw()?;
    // Wheel lane: stacked light fractions per segment, sampled finely enough to show a spoke.
    let samples = 3000;
    let dt = (b - a) / samples as f64;
    let mut rects = Vec::new();
    for m in 0..samples {
        let t = a + (m as f64 + 0.5) * dt;
        let mut y = 2.2;
        for (i, f) in s.light_fractions(t).iter().enumerate() {
            if *f > 0.0 {
                let top = y + 0.9 * f;
                rects.push(Rectangle::new(
                    [((t - 0.5 * dt) * ms, y), ((t + 0.5 * dt) * ms, top)],
                    colour(chips, i, s.n).filled(),
                ));
                y = top;
            }
        }
    }
    chart.draw_series(rects)?;
    // Pattern lane: each slot occurrence in the window.
    let mut labels = Vec::new();
    for (k, &(start, dur)) in s.slots.iter().enumerate() {
        let mut t = start + ((a - start) / s.period).floor() * s.period;
        while t < b {
            let (u, v) = (t.max(a), (t + dur).min(b));
            if v > u {
                chart.draw_series(std::iter::once(Rectangle::new(
                    [(u * ms, 1.2), (v * ms, 2.0)],
                    colour(chips, k, s.n).filled(),
                )))?;
                labels.push((format!("p{k}"), (0.5 * (u + v) * ms, 1.75)));
            }
            t += s.period;
        }
    }
    // Segment names at the middle of each segment passage.
    for i in 0..s.n {
        let end = s.theta_deg.get(i + 1).copied().unwrap_or(360.0);
        let centre =
            (((s.theta_deg[i] + end) / 2.0 - s.offset_deg) / 360.0).rem_euclid(1.0) * s.period;
        let mut t = centre + ((a - centre) / s.period).floor() * s.period;
        while t < b {
            if t > a {
                labels.push((format!("s{i}"), (t * ms, 2.95)));
            }
            t += s.period;
        }
    }
    // Exposure lane.
    let (u, v) = (exp_a.max(a), exp_b.min(b));
    if v > u {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(u * ms, 0.2), (v * ms, 1.0)],
            RGBColor(90, 90, 90).filled(),
        )))?;
    }
    let font = ("sans-serif", 15).into_font().color(&BLACK);
    chart.draw_series(
        labels
            .into_iter()
            .map(|(l, p)| Text::new(l, p, font.clone())),
    )?;
    let lane = ("sans-serif", 16).into_font().color(&BLACK);
    for (name, y) in [
        ("wheel segment (light fraction)", 3.35),
        ("pattern shown", 2.15),
        ("exposure", 1.15),
    ] {
        chart.draw_series(std::iter::once(Text::new(name, (a * ms, y), lane.clone())))?;
    }
    Ok(())
}

/// The summary under the panels: turns, spoke fraction, weight matrix, warnings.
fn draw_text(
    area: &Area,
    cfg: &TimingConfig,
    tw: &TimingWeights,
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    let style = ("sans-serif", 17).into_font().color(&BLACK);
    let mut lines = vec![format!(
        "exposure {} ms = {:.4} turns at {} rev/s, starting {} ms after the index pulse; spot on a spoke {:.3} % of the time",
        cfg.camera.exposure_s * 1e3,
        tw.turns_per_exposure,
        cfg.wheel.rate_hz,
        cfg.camera.start_s * 1e3,
        100.0 * tw.spoke_fraction
    )];
    lines.push("weights w[segment i][pattern k] (identity = aligned, whole turns):".into());
    for (i, row) in tw.w.iter().enumerate() {
        let cells: Vec<String> = row.iter().map(|v| format!("{v:8.5}")).collect();
        lines.push(format!("   s{i}:  {}", cells.join("   ")));
    }
    if tw.warnings.is_empty() {
        lines.push("no warnings".into());
    }
    lines.extend(tw.warnings.iter().map(|w| format!("warning: {w}")));
    for (m, l) in lines.iter().enumerate() {
        area.draw(&Text::new(
            l.clone(),
            (20, 10 + (m as u32 * LINE) as i32),
            style.clone(),
        ))?;
    }
    Ok(())
}

/// One lane of a trigger-chain figure: edges (instants, s) and spans (start, end, s).
pub struct Lane {
    pub name: String,
    pub edges: Vec<f64>,
    pub spans: Vec<(f64, f64)>,
}

/// Write the trigger chain of a run as logged (`lanes` top to bottom) in two panels, each a
/// (title, start s, end s) window: what happened when, as the devices saw it.
pub fn trigger_chain_png(
    path: &Path,
    lanes: &[Lane],
    windows: &[(String, f64, f64)],
) -> Result<()> {
    let height = 70 + 40 * lanes.len() as u32;
    let size = (WIDTH, height * windows.len() as u32);
    crate::plot::render_png(path, size, |root| {
        for (area, (title, a, b)) in root.split_evenly((windows.len(), 1)).iter().zip(windows) {
            draw_lanes(area, lanes, title, *a, *b).map_err(|e| e.to_string())?;
        }
        Ok(())
    })
}

/// One window of the trigger chain: a row per lane, edges as ticks, spans as bars.
fn draw_lanes(
    area: &Area,
    lanes: &[Lane],
    title: &str,
    a: f64,
    b: f64,
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    let (ms, n) = (1e3, lanes.len() as f64);
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .margin_right(32)
        .x_label_area_size(36)
        .y_label_area_size(230)
        .build_cartesian_2d(a * ms..b * ms, -0.5..n - 0.5)?;
    // Lane r is centred on y = n − 1 − r, so the integer ticks name the lanes.
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(lanes.len())
        .y_label_formatter(&|y| {
            let row = n - 1.0 - y.round();
            match lanes.get(row as usize) {
                Some(l) if (y - y.round()).abs() < 1e-6 && row >= 0.0 => l.name.clone(),
                _ => String::new(),
            }
        })
        .x_desc("virtual time (ms)")
        .label_style(("sans-serif", 14))
        .draw()?;
    for (r, lane) in lanes.iter().enumerate() {
        let (lo, hi) = (n - r as f64 - 1.35, n - r as f64 - 0.65);
        let colour = crate::plot::series_color(r);
        let spans = lane.spans.iter().filter(|(u, v)| *v > a && *u < b);
        chart.draw_series(spans.map(|&(u, v)| {
            Rectangle::new(
                [(u.max(a) * ms, lo), (v.min(b) * ms, hi)],
                colour.mix(0.6).filled(),
            )
        }))?;
        let edges = lane.edges.iter().filter(|t| (a..=b).contains(*t));
        chart.draw_series(edges.map(|&t| {
            PathElement::new(vec![(t * ms, lo), (t * ms, hi)], colour.stroke_width(2))
        }))?;
    }
    Ok(())
}
