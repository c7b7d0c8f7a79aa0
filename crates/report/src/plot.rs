//! Plots: PNG previews of cubes (CIE 1931 → sRGB), line plots, and spectra against the truth.

use plotters::element::MultiLineText;
use plotters::prelude::*;
use rayon::prelude::*;
use specmux_core::spectral::{Curve, Grid, Library};
use specmux_core::{Cube, Error, Result};
use specmux_io::png::write_png;
use std::path::Path;

/// Converts spectral cubes to display colour through the CIE 1931 2° observer.
pub struct Colorimetry {
    /// Per band: the weights giving X, Y, Z (light × CMF × step), normalised so white has Y = 1.
    xyz: Vec<[f64; 3]>,
}

impl Colorimetry {
    /// Weights for a cube on `grid`; `light` lights a reflectance cube, None for radiance.
    pub fn new(lib: &Library, grid: &Grid, light: Option<&Curve>) -> Result<Colorimetry> {
        let cmf = lib.table("cmf/cie1931_2deg")?.curves;
        if cmf.len() != 3 {
            return Err(Error::Csv {
                path: lib.path("cmf/cie1931_2deg"),
                line: 0,
                msg: format!("expected columns x, y, z, found {}", cmf.len()),
            });
        }
        let mut xyz: Vec<[f64; 3]> = grid
            .wavelengths()
            .iter()
            .map(|&wl| {
                let l = light.map_or(1.0, |c| c.eval(wl));
                [
                    l * cmf[0].eval(wl),
                    l * cmf[1].eval(wl),
                    l * cmf[2].eval(wl),
                ]
            })
            .collect();
        let white_y: f64 = xyz.iter().map(|v| v[1]).sum();
        if white_y > 0.0 {
            xyz.iter_mut().flatten().for_each(|v| *v /= white_y);
        }
        Ok(Colorimetry { xyz })
    }

    /// CIE XYZ of one spectrum (white reflector or the brightest radiance at exposure 1: Y = 1).
    fn xyz(&self, spectrum: impl Iterator<Item = f64>) -> [f64; 3] {
        let mut c = [0.0f64; 3];
        for (v, w) in spectrum.zip(&self.xyz) {
            for k in 0..3 {
                c[k] += v * w[k];
            }
        }
        c
    }

    /// The full-brightness colour chip of one spectrum on the grid (see [`chip_srgb`]).
    pub fn chip(&self, spectrum: &[f64]) -> [u8; 3] {
        chip_srgb(self.xyz(spectrum.iter().copied()))
    }

    /// An sRGB preview; `exposure` scales Y before the tone curve (1 = white reflector at 1).
    pub fn preview(&self, cube: &Cube, exposure: f64) -> Result<image::RgbImage> {
        if cube.planes != self.xyz.len() {
            return Err(Error::Shape(format!(
                "{} planes for {} bands",
                cube.planes,
                self.xyz.len()
            )));
        }
        let n = cube.pixels();
        let mut rgb = vec![0u8; 3 * n];
        rgb.par_chunks_mut(3 * cube.width)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, px) in row.chunks_exact_mut(3).enumerate() {
                    let p = y * cube.width + x;
                    let c = self.xyz((0..cube.planes).map(|b| cube.data[b * n + p] as f64));
                    px.copy_from_slice(&xyz_to_srgb(c.map(|v| v * exposure)));
                }
            });
        image::RgbImage::from_raw(cube.width as u32, cube.height as u32, rgb)
            .ok_or_else(|| Error::Shape(format!("{}×{} preview", cube.width, cube.height)))
    }
}

/// XYZ (D65 white, Y = 1 white) → 8-bit sRGB (IEC 61966-2-1): the linear matrix, a clip to the
/// gamut, then the sRGB transfer curve.
pub fn xyz_to_srgb(xyz: [f64; 3]) -> [u8; 3] {
    encode_srgb(linear_srgb(xyz))
}

/// The colour of a spectrum at full brightness (its linear sRGB scaled so the largest channel
/// is 1): a colour chip for a filter, whatever its throughput; black for a spectrum with none.
pub fn chip_srgb(xyz: [f64; 3]) -> [u8; 3] {
    let lin = linear_srgb(xyz).map(|v| v.max(0.0));
    let top = lin.iter().cloned().fold(0.0, f64::max);
    encode_srgb(if top > 0.0 { lin.map(|v| v / top) } else { lin })
}

/// XYZ → linear sRGB (IEC 61966-2-1 matrix, D65 white).
fn linear_srgb([x, y, z]: [f64; 3]) -> [f64; 3] {
    [
        3.2406 * x - 1.5372 * y - 0.4986 * z,
        -0.9689 * x + 1.8758 * y + 0.0415 * z,
        0.0557 * x - 0.2040 * y + 1.0570 * z,
    ]
}

/// Linear sRGB, clipped to [0, 1], through the sRGB transfer curve to 8 bits.
fn encode_srgb(lin: [f64; 3]) -> [u8; 3] {
    lin.map(|v| {
        let v = v.clamp(0.0, 1.0);
        let g = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (g * 255.0).round() as u8
    })
}

/// Register the embedded DejaVu Sans as plotters' "sans-serif" once (no system fonts); the
/// error names the plot `path` that needed it.
pub fn register_font(path: &Path) -> Result<()> {
    use std::sync::OnceLock;
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            include_bytes!(concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/assets/DejaVuSans.ttf"
            )),
        )
        .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(Error::Image {
            path: path.to_path_buf(),
            msg: "the embedded font DejaVuSans.ttf is not a valid font".into(),
        })
    }
}

/// A line series for a plot: label (empty: no legend entry), colour index, line style and
/// (x, y) points.
pub struct Series {
    pub label: String,
    pub color: usize,
    pub dashed: bool,
    pub points: Vec<(f64, f64)>,
}

/// Series colours: the ten of Tableau (matplotlib's default cycle), distinct on white and on
/// images.
const SERIES_COLORS: [(u8, u8, u8); 10] = [
    (0x1f, 0x77, 0xb4),
    (0xff, 0x7f, 0x0e),
    (0x2c, 0xa0, 0x2c),
    (0xd6, 0x27, 0x28),
    (0x94, 0x67, 0xbd),
    (0x8c, 0x56, 0x4b),
    (0xe3, 0x77, 0xc2),
    (0x7f, 0x7f, 0x7f),
    (0xbc, 0xbd, 0x22),
    (0x17, 0xbe, 0xcf),
];

/// The colour of series colour index `k`, shared by line plots and the pixel marks on images.
pub fn series_color(k: usize) -> RGBColor {
    let (r, g, b) = SERIES_COLORS[k % SERIES_COLORS.len()];
    RGBColor(r, g, b)
}

/// A tick label for `v` on an axis spanning `span`: as many decimals as a tenth of the span
/// needs (400 on a 300 nm axis, 0.3 on a unit axis), never "-0".
pub fn tick_label(v: f64, span: f64) -> String {
    let step = (span.abs() / 10.0).max(f64::MIN_POSITIVE);
    let decimals = (-step.log10().floor()).clamp(0.0, 9.0) as usize;
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

/// A plot area on a white `w × h` canvas in memory.
pub type Canvas<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// Render a `w × h` plot into memory with `draw` (on a white canvas, the font registered), then
/// write it as PNG atomically; a drawing error names `path`.
pub fn render_png(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&Canvas) -> std::result::Result<(), String>,
) -> Result<()> {
    register_font(path)?;
    let err = |msg: String| Error::Image {
        path: path.to_path_buf(),
        msg,
    };
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        draw(&root).map_err(err)?;
        root.present().map_err(|e| err(e.to_string()))?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| err("plot buffer".into()))?;
    write_png(path, &img)
}

/// A drawing error as the text `render_png` reports.
pub fn show(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// Does the segment a–b meet the axis-aligned box [lo, hi]? (Liang–Barsky clipping.)
fn segment_meets_box(a: (f64, f64), b: (f64, f64), lo: (f64, f64), hi: (f64, f64)) -> bool {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - lo.0),
        (dx, hi.0 - a.0),
        (-dy, a.1 - lo.1),
        (dy, hi.1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else if p < 0.0 {
            t0 = t0.max(q / p);
        } else {
            t1 = t1.min(q / p);
        }
    }
    t0 <= t1
}

/// Where the legend goes: the first plot corner whose box (`frac` of the plot's width and
/// height) no curve crosses, in the order upper right, upper left, lower right, lower left; if
/// every corner is taken, the upper right with the y range raised until the curves stay below
/// the box. Returns the corner and the top of the y range.
pub fn place_legend(
    curves: &[Vec<(f64, f64)>],
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    frac: (f64, f64),
) -> (SeriesLabelPosition, f64) {
    use SeriesLabelPosition::*;
    let (fw, fh) = (frac.0.clamp(0.0, 1.0), frac.1.clamp(0.0, 0.9));
    let norm = |&(x, y): &(f64, f64)| ((x - x0) / (x1 - x0), (y - y0) / (y1 - y0));
    let free = |lo: (f64, f64), hi: (f64, f64)| {
        !curves.iter().any(|c| {
            let pts: Vec<(f64, f64)> = c.iter().map(norm).collect();
            pts.windows(2)
                .any(|s| segment_meets_box(s[0], s[1], lo, hi))
                || (pts.len() == 1 && segment_meets_box(pts[0], pts[0], lo, hi))
        })
    };
    for (pos, (u, v)) in [
        (UpperRight, (1.0 - fw, 1.0 - fh)),
        (UpperLeft, (0.0, 1.0 - fh)),
        (LowerRight, (1.0 - fw, 0.0)),
        (LowerLeft, (0.0, 0.0)),
    ] {
        if free((u, v), (u + fw, v + fh)) {
            return (pos, y1);
        }
    }
    // The data keep the lower 1 − fh of the new range, y1' − y0 = (y1 − y0) / (1 − fh), and a
    // gap of 2 % of the old range below the box.
    (UpperRight, y0 + (y1 - y0) * (1.0 / (1.0 - fh) + 0.02))
}

/// Margin, x and y label-area sizes and fonts of the line plots, in pixels.
const MARGIN: u32 = 12;
const X_LABELS: u32 = 45;
const Y_LABELS: u32 = 70;
const LEGEND_FONT: u32 = 15;

/// A line plot written as PNG; rendered into memory, then written atomically.
pub fn line_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<()> {
    keyed_line_plot(path, title, (x_label, y_label), series, &[])
}

/// A line plot whose legend also holds `key`: black legend-only entries (label, dashed) that
/// say what a line style means. The legend goes where it covers no curve (`place_legend`).
pub fn keyed_line_plot(
    path: &Path,
    title: &str,
    (x_label, y_label): (&str, &str),
    series: &[Series],
    key: &[(&str, bool)],
) -> Result<()> {
    let curves: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|s| {
            let fin = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
            s.points.iter().filter(fin).cloned().collect()
        })
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in curves.iter().flatten() {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x0 > x1 {
        return Err(Error::Image {
            path: path.to_path_buf(),
            msg: "nothing finite to plot".into(),
        });
    }
    let x1 = x1.max(x0 + 1e-9);
    let pad = 0.05 * (y1 - y0).max(1e-12);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let entries: Vec<(String, RGBColor, bool)> = series
        .iter()
        .filter(|s| !s.label.is_empty())
        .map(|s| (s.label.clone(), series_color(s.color), s.dashed))
        .chain(key.iter().map(|&(l, d)| (l.to_string(), BLACK, d)))
        .collect();
    render_png(path, (900, 560), |root| {
        let area = root.titled(title, ("sans-serif", 22)).map_err(show)?;
        let (aw, ah) = area.dim_in_pixel();
        let plot = (
            aw.saturating_sub(2 * MARGIN + Y_LABELS).max(1) as f64,
            ah.saturating_sub(2 * MARGIN + X_LABELS).max(1) as f64,
        );
        let font = ("sans-serif", LEGEND_FONT).into_font();
        let mut text = MultiLineText::<_, &str>::new((0, 0), font.clone());
        entries.iter().for_each(|e| text.push_line(e.0.as_str()));
        let (lw, lh) = text.estimate_dimension().map_err(show)?;
        // The legend box: text, 30 px for the line sample, 10 px margins, 5 px from the edge.
        let frac = (
            (lw + 30 + 20 + 10) as f64 / plot.0,
            (lh + 20 + 10) as f64 / plot.1,
        );
        let (pos, top) = if entries.is_empty() {
            (SeriesLabelPosition::UpperRight, y1)
        } else {
            place_legend(&curves, (x0, x1), (y0, y1), frac)
        };
        let mut chart = ChartBuilder::on(&area)
            .margin(MARGIN)
            .x_label_area_size(X_LABELS)
            .y_label_area_size(Y_LABELS)
            .build_cartesian_2d(x0..x1, y0..top)
            .map_err(show)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .x_label_formatter(&|v| tick_label(*v, x1 - x0))
            .y_label_formatter(&|v| tick_label(*v, top - y0))
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(show)?;
        for (s, pts) in series.iter().zip(curves) {
            let style = ShapeStyle::from(series_color(s.color)).stroke_width(2);
            if s.dashed {
                chart.draw_series(DashedLineSeries::new(pts, 8, 5, style))
            } else {
                chart.draw_series(LineSeries::new(pts, style))
            }
            .map_err(show)?;
        }
        for (label, color, dashed) in entries.iter().cloned() {
            let style = ShapeStyle::from(color).stroke_width(2);
            chart
                .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
                .map_err(show)?
                .label(label)
                .legend(move |(x, y)| {
                    // A 20-pixel sample: three dashes, or three touching strokes.
                    let d = if dashed {
                        [(0, 5), (8, 13), (16, 20)]
                    } else {
                        [(0, 7), (7, 14), (14, 20)]
                    };
                    let seg = |(a, b)| PathElement::new(vec![(a, 0), (b, 0)], style);
                    EmptyElement::at((x, y)) + seg(d[0]) + seg(d[1]) + seg(d[2])
                });
        }
        if entries.is_empty() {
            return Ok(());
        }
        chart
            .configure_series_labels()
            .position(pos)
            .label_font(font.clone())
            .background_style(WHITE.mix(0.9))
            .border_style(BLACK)
            .draw()
            .map_err(show)
    })
}

/// `count` pixels of `truth` (or of a reconstruction where there is none) with distinct
/// spectra, among the pixels between half the median brightness and twice its 90th percentile
/// (a dark pixel's angle is its noise's, and a radiance scene's black corners would win it; a
/// lamp in view would flatten every other curve of the plot): one at the 90th percentile, then
/// each farthest in spectral angle from those already chosen. Searched on a coarse grid
/// that keeps a twenty-fourth of the side from the edges, so a pixel's mark on the comparison
/// panel is not cut by the frame's border.
pub fn distinct_pixels(truth: &Cube, count: usize) -> Vec<(usize, usize)> {
    let side = truth.width.min(truth.height);
    let (step, margin) = ((side / 48).max(1), side / 24);
    let (w, h) = (truth.width - margin, truth.height - margin);
    let cands: Vec<(usize, usize, Vec<f32>)> = (margin.max(step / 2)..h)
        .step_by(step)
        .flat_map(|y| (margin.max(step / 2)..w).step_by(step).map(move |x| (x, y)))
        .map(|(x, y)| (x, y, truth.spectrum(x, y)))
        .collect();
    let norm = |v: &[f32]| v.iter().map(|a| (*a as f64).powi(2)).sum::<f64>().sqrt();
    let angle = |a: &[f32], b: &[f32]| {
        let d: f64 = a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum();
        (d / (norm(a) * norm(b)).max(1e-30)).clamp(-1.0, 1.0).acos()
    };
    let mut norms: Vec<f64> = cands.iter().map(|c| norm(&c.2)).collect();
    norms.sort_by(f64::total_cmp);
    let Some(&median) = norms.get(norms.len() / 2) else {
        return Vec::new();
    };
    let p90 = norms[norms.len() * 9 / 10];
    let (floor, ceiling) = (0.5 * median, 2.0 * p90);
    let lit: Vec<&(usize, usize, Vec<f32>)> = (cands.iter())
        .filter(|c| {
            let n = norm(&c.2);
            n > 0.0 && n >= floor && n <= ceiling
        })
        .collect();
    let off_p90 = |c: &&&(usize, usize, Vec<f32>)| (norm(&c.2) - p90).abs();
    let Some(&first) = lit.iter().min_by(|a, b| off_p90(a).total_cmp(&off_p90(b))) else {
        return Vec::new();
    };
    let mut chosen = vec![first];
    while chosen.len() < count.min(lit.len()) {
        // A pixel already chosen is at angle 0 from itself, and may tie with the farthest.
        let unchosen = lit
            .iter()
            .filter(|c| !chosen.iter().any(|d| std::ptr::eq(**c, *d)));
        let next = unchosen.max_by(|a, b| {
            let da = chosen
                .iter()
                .map(|c| angle(&a.2, &c.2))
                .fold(f64::MAX, f64::min);
            let db = chosen
                .iter()
                .map(|c| angle(&b.2, &c.2))
                .fold(f64::MAX, f64::min);
            da.total_cmp(&db)
        });
        match next {
            Some(&n) => chosen.push(n),
            None => break,
        }
    }
    chosen.iter().map(|c| (c.0, c.1)).collect()
}

/// Truth (solid) against reconstruction (dashed) at `pixels`, one colour per pixel (the colours
/// of the marks on the comparison panel); without a truth, the reconstruction alone.
pub fn spectra_plot(
    path: &Path,
    grid: &Grid,
    (truth, est): (Option<&Cube>, &Cube),
    pixels: &[(usize, usize)],
    y_label: &str,
) -> Result<()> {
    let wl = grid.wavelengths();
    let curve = |cube: &Cube, (x, y): (usize, usize)| -> Vec<(f64, f64)> {
        wl.iter()
            .zip(cube.spectrum(x, y))
            .map(|(&l, v)| (l, v as f64))
            .collect()
    };
    let mut series = Vec::new();
    for (k, &(x, y)) in pixels.iter().enumerate() {
        let label = format!("{} ({x}, {y})", k + 1);
        if let Some(t) = truth {
            series.push(Series {
                label: label.clone(),
                color: k,
                dashed: false,
                points: curve(t, (x, y)),
            });
        }
        series.push(Series {
            label: if truth.is_some() {
                String::new()
            } else {
                label
            },
            color: k,
            dashed: truth.is_some(),
            points: curve(est, (x, y)),
        });
    }
    let (title, key): (&str, &[(&str, bool)]) = if truth.is_some() {
        (
            "Spectra at the marked pixels: truth and reconstruction",
            &[("truth", false), ("reconstruction", true)],
        )
    } else {
        (
            "Reconstructed spectra at the marked pixels (no truth given)",
            &[],
        )
    };
    keyed_line_plot(path, title, ("wavelength (nm)", y_label), &series, key)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn library() -> Library {
        Library::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../spectra"))
    }

    /// The sRGB colour of one reflectance spectrum on 400–700 nm (10 nm) under D65.
    fn colour_of(reflectance: impl Fn(f64) -> f32) -> [u8; 3] {
        let lib = library();
        let grid = Grid::new(400.0, 10.0, 31).unwrap();
        let d65 = lib.curve("illuminants/D65").unwrap();
        let col = Colorimetry::new(&lib, &grid, Some(&d65)).unwrap();
        let mut cube = Cube::zeros(1, 1, grid.count);
        cube.data = grid.wavelengths().into_iter().map(reflectance).collect();
        col.preview(&cube, 1.0).unwrap().get_pixel(0, 0).0
    }

    #[test]
    fn each_preview_pixel_is_the_colour_of_its_own_spectrum() {
        // 3 × 2 pixels, each a flat reflectance of its own level: rows and columns in place.
        let level = |p: usize| 0.1 + 0.15 * p as f32;
        let lib = library();
        let grid = Grid::new(400.0, 10.0, 31).unwrap();
        let d65 = lib.curve("illuminants/D65").unwrap();
        let col = Colorimetry::new(&lib, &grid, Some(&d65)).unwrap();
        let mut cube = Cube::zeros(3, 2, grid.count);
        for b in 0..grid.count {
            for p in 0..6 {
                cube.data[b * 6 + p] = level(p);
            }
        }
        let img = col.preview(&cube, 1.0).unwrap();
        for p in 0..6 {
            let got = img.get_pixel((p % 3) as u32, (p / 3) as u32).0;
            assert_eq!(got, colour_of(|_| level(p)), "pixel {p}");
        }
    }

    #[test]
    fn a_flat_reflectance_under_d65_is_neutral_grey() {
        // Y = 0.5 → sRGB 0.5^(1/2.4)·1.055 − 0.055 = 0.7354 → 187.5.
        let [r, g, b] = colour_of(|_| 0.5);
        for c in [r, g, b] {
            assert!((187..=189).contains(&c), "{:?}", [r, g, b]);
        }
        assert!(r.abs_diff(g) <= 1 && g.abs_diff(b) <= 1, "{:?}", [r, g, b]);
        assert_eq!(colour_of(|_| 1.0), [255; 3]);
        assert_eq!(colour_of(|_| 0.0), [0; 3]);
    }

    #[test]
    fn narrow_bands_take_their_hue() {
        let band = |c: f64| move |wl: f64| if (wl - c).abs() < 25.0 { 1.0 } else { 0.0 };
        let [r, g, b] = colour_of(band(620.0));
        assert!(r > 2 * g.max(b), "620 nm: {:?}", [r, g, b]);
        let [r, g, b] = colour_of(band(450.0));
        assert!(b > 2 * r.max(g), "450 nm: {:?}", [r, g, b]);
        let [r, g, b] = colour_of(band(530.0));
        assert!(g > r.max(b), "530 nm: {:?}", [r, g, b]);
    }

    #[test]
    fn a_chip_is_the_hue_at_full_brightness() {
        // A dim grey filter is white as a chip; a dim red band is as red as a bright one.
        assert_eq!(chip_srgb([0.1 * 0.9505, 0.1, 0.1 * 1.089]), [255, 255, 255]);
        let lib = library();
        let grid = Grid::new(400.0, 10.0, 31).unwrap();
        let col = Colorimetry::new(&lib, &grid, None).unwrap();
        let red: Vec<f64> = grid
            .wavelengths()
            .iter()
            .map(|&w| if w >= 600.0 { 1.0 } else { 0.0 })
            .collect();
        let dim: Vec<f64> = red.iter().map(|v| 0.05 * v).collect();
        let [r, g, b] = col.chip(&red);
        assert_eq!(col.chip(&dim), [r, g, b]);
        assert!(r == 255 && r > 2 * g.max(b), "{:?}", [r, g, b]);
        assert_eq!(col.chip(&vec![0.0; grid.count]), [0, 0, 0]);
    }

    /// A radiance scene: a bright lamp, walls of two colours, a grey ceiling and a black border.
    /// The pixels are the ceiling (at the 90th percentile of brightness) and the two walls — not
    /// the lamp, which would flatten the other curves, nor the border, whose zero spectra have no
    /// angle, nor the dim corner pixels whose noise would be the farthest in angle.
    #[test]
    fn distinct_pixels_skip_the_dark_ones() {
        let (w, h) = (96, 96);
        let mut c = Cube::zeros(w, h, 3);
        for y in 0..h {
            for x in 0..w {
                let v: [f32; 3] = match (x, y) {
                    (0..=7, _) | (_, 0..=7) => [0.0, 0.0, 0.0],
                    (8..=11, 8..=11) => [1e-3, 0.0, 2e-3],
                    (40..=47, 40..=47) => [100.0, 100.0, 100.0],
                    (_, 8..=23) => [4.0, 4.0, 4.0],
                    (_, 0..=47) => [5.0, 1.0, 1.0],
                    _ => [1.0, 5.0, 1.0],
                };
                for (k, vk) in v.iter().enumerate() {
                    c.data[k * w * h + y * w + x] = *vk;
                }
            }
        }
        let px = distinct_pixels(&c, 3);
        let at = |&(x, y): &(usize, usize)| c.spectrum(x, y);
        assert_eq!(at(&px[0]), vec![4.0, 4.0, 4.0]);
        let mut rest: Vec<Vec<f32>> = px[1..].iter().map(at).collect();
        rest.sort_by(|a, b| a[0].total_cmp(&b[0]));
        assert_eq!(
            rest,
            vec![vec![1.0, 5.0, 1.0], vec![5.0, 1.0, 1.0]],
            "{px:?}"
        );
    }

    /// Asked for more pixels than are lit, it gives each lit pixel once (two of a 2 × 2 cube's
    /// four: two are black), not one of them twice.
    #[test]
    fn distinct_pixels_never_repeat_a_pixel() {
        let mut c = Cube::zeros(2, 2, 3);
        for (p, v) in [(2, 1.0), (3, 2.0)] {
            for k in 0..3 {
                c.data[k * 4 + p] = v * (k + 1) as f32;
            }
        }
        let mut px = distinct_pixels(&c, 3);
        px.sort();
        assert_eq!(px, vec![(0, 1), (1, 1)]);
    }

    #[test]
    fn tick_labels_take_the_decimals_the_axis_needs() {
        assert_eq!(tick_label(400.0, 300.0), "400");
        assert_eq!(tick_label(0.30000000000000004, 1.0), "0.3");
        assert_eq!(tick_label(0.005, 0.03), "0.005");
        assert_eq!(tick_label(-1e-9, 1.0), "0.0");
        assert_eq!(tick_label(-0.25, 1.0), "-0.2");
        assert_eq!(tick_label(1250.0, 4000.0), "1250");
    }

    #[test]
    fn a_segment_through_a_box_meets_it_without_a_vertex_inside() {
        let (lo, hi) = ((0.8, 0.8), (1.0, 1.0));
        assert!(segment_meets_box((0.7, 1.0), (1.0, 0.7), lo, hi));
        assert!(!segment_meets_box((0.5, 1.0), (1.0, 0.5), lo, hi));
        assert!(!segment_meets_box((0.0, 0.9), (0.7, 0.9), lo, hi));
        assert!(segment_meets_box((0.9, 0.9), (0.9, 0.9), lo, hi));
    }

    #[test]
    fn the_legend_takes_a_free_corner_or_headroom() {
        use SeriesLabelPosition::*;
        let unit = (0.0, 1.0);
        let frac = (0.3, 0.2);
        // A rising diagonal crosses the upper-right box; the upper left is free.
        let rising = vec![(0.0, 0.0), (1.0, 1.0)];
        let (pos, top) = place_legend(std::slice::from_ref(&rising), unit, unit, frac);
        assert!(matches!(pos, UpperLeft) && top == 1.0);
        // A falling one crosses the upper left; a point in the upper-right box blocks it too.
        let falling = vec![(0.0, 1.0), (1.0, 0.0)];
        let (pos, _) = place_legend(&[falling.clone(), vec![(0.9, 0.9)]], unit, unit, frac);
        assert!(matches!(pos, LowerLeft), "{pos:?}");
        // Both diagonals take every corner: the range grows until the top strip is free.
        let (pos, top) = place_legend(&[rising.clone(), falling.clone()], unit, unit, frac);
        assert!(
            matches!(pos, UpperRight) && (top - 1.27).abs() < 1e-12,
            "{pos:?} {top}"
        );
        let (pos, again) = place_legend(&[rising, falling], unit, (0.0, top), frac);
        assert!(matches!(pos, UpperRight) && again == top, "{pos:?} {again}");
    }
}
