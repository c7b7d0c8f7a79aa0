//! The design figures: filter curves, and the Fourier plane with its windows, harmonics and the
//! measured scene spectrum. Legends sit in a column beside the plot so they never cover data.

use crate::layout::Layout;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use specmux_core::spectral::Curve;
use specmux_core::Result;
use specmux_report::plot::render_png;
use std::path::Path;

/// Canvas of the curve plots, and of the Fourier plane (its data area square: 612 × 612 px).
const SIZE: (u32, u32) = (1100, 620);
const SQUARE: (u32, u32) = (1000, 716);
/// Width of the legend column on the right.
const LEGEND_W: u32 = 300;

/// A drawing area of the in-memory bitmap.
type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Render into memory with `draw(plot area, legend area)`, then write the PNG atomically.
fn render(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&Area, &Area) -> std::result::Result<(), String>,
) -> Result<()> {
    render_png(path, (w, h), |root| {
        let (plot, legend) = root.split_horizontally(w - LEGEND_W);
        draw(&plot, &legend)
    })
}

/// A line of a plot: its style and, where it must be told from a line of the same colour, its
/// dash (length, gap) in pixels.
#[derive(Clone, Copy)]
struct Line {
    style: ShapeStyle,
    dash: Option<(u32, u32)>,
}

impl From<ShapeStyle> for Line {
    fn from(style: ShapeStyle) -> Line {
        Line { style, dash: None }
    }
}

/// One legend entry per (label, line) in the legend column, from the top.
fn legend(area: &Area, entries: &[(String, Line)]) -> std::result::Result<(), String> {
    let font = ("sans-serif", 15).into_font();
    for (k, (label, line)) in entries.iter().enumerate() {
        let y = 60 + 24 * k as i32;
        let sample = vec![(8, y), (38, y)];
        match line.dash {
            None => area.draw(&PathElement::new(sample, line.style)),
            Some((on, off)) => area.draw(&plotters::element::DashedPathElement::new(
                sample, on, off, line.style,
            )),
        }
        .map_err(|e| e.to_string())?;
        area.draw(&Text::new(label.clone(), (46, y - 8), font.clone()))
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// A curve's name for the legend: a curve written beside the outputs is named by its absolute
/// path, which would run off the image; its folder and stem (`design/gauss-580-60`) name it.
fn legend_name(name: &str) -> String {
    let p = Path::new(name);
    match (
        p.is_absolute(),
        p.parent().and_then(Path::file_name),
        p.file_stem(),
    ) {
        (true, Some(dir), Some(stem)) => {
            format!("{}/{}", dir.to_string_lossy(), stem.to_string_lossy())
        }
        _ => name.to_string(),
    }
}

/// Each curve in its filter's own colour (`chips`: full-brightness sRGB), darkened to show on
/// white; a curve whose colour an earlier one nearly shares is dashed, a third dotted, so that
/// the legend tells them apart.
fn lines(chips: &[[u8; 3]]) -> Vec<Line> {
    const DASHES: [Option<(u32, u32)>; 3] = [None, Some((10, 6)), Some((3, 4))];
    let near = |a: &[u8; 3], b: &[u8; 3]| {
        let d2: i32 = (0..3).map(|k| (a[k] as i32 - b[k] as i32).pow(2)).sum();
        d2 < 60 * 60
    };
    chips
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let same = chips[..k].iter().filter(|d| near(c, d)).count();
            let dark = |v: u8| (v as f64 * 0.8) as u8;
            Line {
                style: RGBColor(dark(c[0]), dark(c[1]), dark(c[2])).stroke_width(2),
                dash: DASHES[same.min(2)],
            }
        })
        .collect()
}

/// Transmittance of each curve over `range_nm`, each in its own colour (`chips`, one per curve).
pub fn curves(
    path: &Path,
    title: &str,
    curves: &[&Curve],
    chips: &[[u8; 3]],
    range_nm: (f64, f64),
) -> Result<()> {
    render(path, SIZE, |plot, leg| {
        let mut chart = ChartBuilder::on(plot)
            .caption(title, ("sans-serif", 20))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(range_nm.0..range_nm.1, 0.0..1.05)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("wavelength (nm)")
            .y_desc("transmittance (fraction)")
            .draw()
            .map_err(|e| e.to_string())?;
        let mut entries = Vec::new();
        for (c, line) in curves.iter().zip(lines(chips)) {
            let pts = c
                .wavelengths()
                .iter()
                .zip(c.values())
                .filter(|(l, _)| (range_nm.0..=range_nm.1).contains(*l))
                .map(|(&l, &v)| (l, v));
            match line.dash {
                None => chart.draw_series(LineSeries::new(pts, line.style)),
                Some((on, off)) => {
                    chart.draw_series(DashedLineSeries::new(pts, on, off, line.style))
                }
            }
            .map_err(|e| e.to_string())?;
            entries.push((legend_name(&c.name), line));
        }
        legend(leg, &entries)
    })
}

/// The Fourier plane (cycles/pixel, DC in the centre): the scene power `spectrum` (N × N,
/// row-major, unshifted, drawn as log10 relative to its peak), the crop windows of `layout`, its
/// 2ω harmonics (×) and its sums/differences ω_i ± ω_j (○).
pub fn fourier_plane(path: &Path, title: &str, layout: &Layout, spectrum: &[f64]) -> Result<()> {
    let n = layout.size as i64;
    let peak = spectrum.iter().cloned().fold(f64::MIN_POSITIVE, f64::max);
    render(path, SQUARE, |plot, leg| {
        let mut chart = ChartBuilder::on(plot)
            .caption(title, ("sans-serif", 18))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5..0.5, -0.5..0.5)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("fx (cycles/pixel)")
            .y_desc("fy (cycles/pixel)")
            .draw()
            .map_err(|e| e.to_string())?;
        let f = |k: i64| k as f64 / n as f64;
        let bins = (-n / 2..n - n / 2).flat_map(|ky| (-n / 2..n - n / 2).map(move |kx| (kx, ky)));
        chart
            .draw_series(bins.map(|(kx, ky)| {
                let p = spectrum[(ky.rem_euclid(n) * n + kx.rem_euclid(n)) as usize];
                // log10(p/peak) over 8 decades → grey 255 (faint) … 40 (strong).
                let t = ((p / peak).max(1e-8).log10() / 8.0 + 1.0).clamp(0.0, 1.0);
                let g = (255.0 - 215.0 * t) as u8;
                let half = 0.5 / n as f64;
                Rectangle::new(
                    [(f(kx) - half, f(ky) - half), (f(kx) + half, f(ky) + half)],
                    RGBColor(g, g, g).filled(),
                )
            }))
            .map_err(|e| e.to_string())?;
        let mut entries = vec![(
            "scene power, log10 (8 decades)".to_string(),
            Line::from(ShapeStyle::from(RGBColor(90, 90, 90)).stroke_width(8)),
        )];
        entries.extend(draw_windows(&mut chart, layout)?);
        legend(leg, &entries)
    })
}

type Chart<'a> = ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Windows (DC black; +ω_i in colour i, thick; −ω_i thin), harmonics and sum/difference terms.
fn draw_windows(
    chart: &mut Chart<'_>,
    layout: &Layout,
) -> std::result::Result<Vec<(String, Line)>, String> {
    let n = layout.size as f64;
    let half = layout.window as f64 / 2.0 / n;
    let wrap = |v: f64| (v + 0.5).rem_euclid(1.0) - 0.5;
    // A window that crosses the edge of the plane is drawn with its periodic copies, clipped.
    let rect = |cx: f64, cy: f64, style: ShapeStyle| {
        let (cx, cy) = (wrap(cx), wrap(cy));
        let clip = |v: f64| v.clamp(-0.5, 0.5);
        [-1.0, 0.0, 1.0]
            .into_iter()
            .flat_map(|dx| [-1.0, 0.0, 1.0].map(|dy| (cx + dx, cy + dy)))
            .filter(|&(x, y)| {
                (x - half < 0.5 && x + half > -0.5) && (y - half < 0.5 && y + half > -0.5)
            })
            .map(move |(x, y)| {
                let corners = [
                    (clip(x - half), clip(y - half)),
                    (clip(x + half), clip(y + half)),
                ];
                Rectangle::new(corners, style)
            })
            .collect::<Vec<_>>()
    };
    let e = |e: DrawingAreaErrorKind<_>| e.to_string();
    let mut entries: Vec<(String, Line)> = vec![("DC window".into(), BLACK.stroke_width(2).into())];
    chart
        .draw_series(rect(0.0, 0.0, BLACK.stroke_width(2)))
        .map_err(e)?;
    for (i, &(bx, by)) in layout.bins.iter().enumerate() {
        let c = Palette99::pick(i).to_rgba();
        let (fx, fy) = (bx as f64 / n, by as f64 / n);
        chart
            .draw_series(rect(fx, fy, c.stroke_width(3)).into_iter().chain(rect(
                -fx,
                -fy,
                c.stroke_width(1),
            )))
            .map_err(e)?;
        let h = (wrap(2.0 * fx), wrap(2.0 * fy));
        let marks = [h, (-h.0, -h.1)].map(|p| Cross::new(p, 6, c.stroke_width(2)));
        chart.draw_series(marks).map_err(e)?;
        entries.push((
            format!("ω{i} = ({bx}, {by})/{} (+ thick, − thin)", layout.size),
            c.stroke_width(3).into(),
        ));
    }
    let terms = layout.intermodulation();
    chart
        .draw_series(
            terms
                .iter()
                .map(|&(x, y)| Circle::new((x as f64 / n, y as f64 / n), 4, BLACK.stroke_width(1))),
        )
        .map_err(e)?;
    entries.push((
        "× 2ω_i harmonic (colour of i)".into(),
        BLACK.stroke_width(1).into(),
    ));
    entries.push(("○ ω_i ± ω_j".into(), BLACK.stroke_width(1).into()));
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::{legend_name, lines};

    /// Two blues and a red: the red solid, the first blue solid, the second dashed.
    #[test]
    fn a_curve_of_a_colour_already_drawn_is_dashed() {
        let l = lines(&[[40, 60, 230], [230, 30, 20], [50, 70, 220]]);
        let dashes: Vec<_> = l.iter().map(|x| x.dash).collect();
        assert_eq!(dashes, vec![None, None, Some((10, 6))]);
    }

    #[test]
    fn a_curve_written_beside_the_outputs_is_named_by_folder_and_stem() {
        assert_eq!(
            legend_name("/tmp/out/filters/design/gauss-580-60.csv"),
            "design/gauss-580-60"
        );
        assert_eq!(legend_name("wheel/red"), "wheel/red");
    }
}
