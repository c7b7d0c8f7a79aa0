//! Plots: PNG previews of cubes (CIE 1931 → sRGB), line plots, and spectra against the truth.

use plotters::prelude::*;
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

    /// An sRGB preview; `exposure` scales Y before the tone curve (1 = white reflector at 1).
    pub fn preview(&self, cube: &Cube, exposure: f64) -> Result<image::RgbImage> {
        if cube.planes != self.xyz.len() {
            return Err(Error::Shape(format!(
                "{} planes for {} bands",
                cube.planes,
                self.xyz.len()
            )));
        }
        let mut img = image::RgbImage::new(cube.width as u32, cube.height as u32);
        for (p, px) in img.pixels_mut().enumerate() {
            let mut c = [0.0f64; 3];
            for (b, w) in self.xyz.iter().enumerate() {
                let v = cube.plane(b)[p] as f64;
                for k in 0..3 {
                    c[k] += v * w[k];
                }
            }
            let [x, y, z] = c.map(|v| v * exposure);
            // XYZ (D65 white) → linear sRGB (IEC 61966-2-1), then the sRGB transfer curve.
            let lin = [
                3.2406 * x - 1.5372 * y - 0.4986 * z,
                -0.9689 * x + 1.8758 * y + 0.0415 * z,
                0.0557 * x - 0.2040 * y + 1.0570 * z,
            ];
            *px = image::Rgb(lin.map(|v| {
                let v = v.clamp(0.0, 1.0);
                let g = if v <= 0.003_130_8 {
                    12.92 * v
                } else {
                    1.055 * v.powf(1.0 / 2.4) - 0.055
                };
                (g * 255.0).round() as u8
            }));
        }
        Ok(img)
    }
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

/// A line series for a plot: label, colour index and (x, y) points.
pub struct Series {
    pub label: String,
    pub color: usize,
    pub dashed: bool,
    pub points: Vec<(f64, f64)>,
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
    write_png(path, image::DynamicImage::ImageRgb8(img))
}

/// A line plot written as PNG; rendered into memory, then written atomically.
pub fn line_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<()> {
    let pts = series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x0 > x1 {
        return Err(Error::Image {
            path: path.to_path_buf(),
            msg: "nothing finite to plot".into(),
        });
    }
    let pad = 0.05 * (y1 - y0).max(1e-12);
    render_png(path, (900, 560), |root| {
        let e = |e: &dyn std::fmt::Display| e.to_string();
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1.max(x0 + 1e-9), (y0 - pad)..(y1 + pad))
            .map_err(|x| e(&x))?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .draw()
            .map_err(|x| e(&x))?;
        for s in series {
            let color = Palette99::pick(s.color).to_rgba();
            let style = ShapeStyle::from(color).stroke_width(2);
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .cloned()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            let anno = if s.dashed {
                chart.draw_series(DashedLineSeries::new(pts, 6, 4, style))
            } else {
                chart.draw_series(LineSeries::new(pts, style))
            }
            .map_err(|x| e(&x))?;
            anno.label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| e(&x))
    })
}

/// Four pixels with distinct truth spectra: the brightest, then each farthest in spectral angle
/// from those already chosen (searched on a coarse grid).
pub fn distinct_pixels(truth: &Cube, count: usize) -> Vec<(usize, usize)> {
    let step = (truth.width.min(truth.height) / 48).max(1);
    let cands: Vec<(usize, usize, Vec<f32>)> = (step / 2..truth.height)
        .step_by(step)
        .flat_map(|y| (step / 2..truth.width).step_by(step).map(move |x| (x, y)))
        .map(|(x, y)| (x, y, truth.spectrum(x, y)))
        .collect();
    let norm = |v: &[f32]| v.iter().map(|a| (*a as f64).powi(2)).sum::<f64>().sqrt();
    let angle = |a: &[f32], b: &[f32]| {
        let d: f64 = a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum();
        (d / (norm(a) * norm(b)).max(1e-30)).clamp(-1.0, 1.0).acos()
    };
    let Some(first) = cands
        .iter()
        .max_by(|a, b| norm(&a.2).total_cmp(&norm(&b.2)))
    else {
        return Vec::new();
    };
    let mut chosen = vec![first];
    while chosen.len() < count.min(cands.len()) {
        let next = cands.iter().filter(|c| norm(&c.2) > 0.0).max_by(|a, b| {
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
            Some(n) => chosen.push(n),
            None => break,
        }
    }
    chosen.iter().map(|c| (c.0, c.1)).collect()
}

/// Truth (solid) against reconstruction (dashed) at four spectrally distinct pixels.
pub fn spectra_plot(path: &Path, grid: &Grid, truth: &Cube, est: &Cube) -> Result<()> {
    let wl = grid.wavelengths();
    let mut series = Vec::new();
    for (k, (x, y)) in distinct_pixels(truth, 4).into_iter().enumerate() {
        for (cube, dashed, tag) in [(truth, false, "truth"), (est, true, "recon")] {
            series.push(Series {
                label: format!("({x},{y}) {tag}"),
                color: k,
                dashed,
                points: wl
                    .iter()
                    .zip(cube.spectrum(x, y))
                    .map(|(&l, v)| (l, v as f64))
                    .collect(),
            });
        }
    }
    line_plot(
        path,
        "Spectra: truth (solid) and reconstruction (dashed)",
        "wavelength (nm)",
        "value",
        &series,
    )
}
