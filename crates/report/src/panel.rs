//! Image figures: pictures on pixel or frequency axes with square pixels, scalar fields through a
//! colour map with a labelled colour bar, numbered pixel marks; and the comparison panel of truth,
//! reconstruction and per-pixel error.

use crate::plot::{render_png, series_color, show, tick_label, Canvas, Colorimetry};
use plotters::prelude::*;
use specmux_core::spectral::Library;
use specmux_core::{Cube, Error, Result};
use specmux_io::output_set::OutputSet;
use specmux_twin::experiment::Experiment;
use std::ops::Range;
use std::path::Path;

/// What a drawing step returns: a drawing error as text (see `render_png`).
type Draw<T = ()> = std::result::Result<T, String>;

/// A sequential colour map from [0, 1] to 8-bit RGB.
#[derive(Clone, Copy, Debug)]
pub enum ColorMap {
    /// Black to white: intensities.
    Grey,
    /// Viridis (perceptually uniform, lightness rising): magnitudes and errors.
    Viridis,
}

/// Viridis at t = 0, 1/8, …, 1 (the nine-colour viridis of matplotlib and R).
const VIRIDIS: [[u8; 3]; 9] = [
    [0x44, 0x01, 0x54],
    [0x47, 0x2d, 0x7b],
    [0x3b, 0x52, 0x8b],
    [0x2c, 0x72, 0x8e],
    [0x21, 0x90, 0x8c],
    [0x27, 0xad, 0x81],
    [0x5d, 0xc8, 0x63],
    [0xaa, 0xdc, 0x32],
    [0xfd, 0xe7, 0x25],
];

impl ColorMap {
    /// The colour at `t`, clamped to [0, 1] (NaN reads as 0).
    pub fn rgb(self, t: f64) -> [u8; 3] {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        match self {
            ColorMap::Grey => [(255.0 * t).round() as u8; 3],
            ColorMap::Viridis => {
                let s = t * (VIRIDIS.len() - 1) as f64;
                let i = (s.floor() as usize).min(VIRIDIS.len() - 2);
                let f = s - i as f64;
                let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
                [0, 1, 2].map(|k| (a[k] as f64 + f * (b[k] as f64 - a[k] as f64)).round() as u8)
            }
        }
    }
}

/// The finite minimum and maximum of `v`; a constant or empty field gets a span of 1.
pub fn finite_range(v: &[f32]) -> (f64, f64) {
    let (lo, hi) = v
        .iter()
        .filter(|x| x.is_finite())
        .fold((f64::MAX, f64::MIN), |(a, b), &x| {
            (a.min(x as f64), b.max(x as f64))
        });
    if lo > hi {
        (0.0, 1.0)
    } else if lo == hi {
        (lo - 0.5, hi + 0.5)
    } else {
        (lo, hi)
    }
}

/// How a field shrinks onto fewer screen pixels: antialiased as the eye sees it (an image), or
/// the maximum of the cells each screen pixel covers (a spectrum, whose one-bin peaks must stay).
#[derive(Clone, Copy, Debug)]
pub enum Reduce {
    Smooth,
    Max,
}

/// A scalar image on a `width × height` grid (row 0 at the top), shown through `map` over
/// `range`, the colour bar labelled `unit`.
pub struct Field<'a> {
    pub values: &'a [f32],
    pub width: usize,
    pub height: usize,
    pub map: ColorMap,
    pub range: (f64, f64),
    pub reduce: Reduce,
    pub unit: String,
}

impl Field<'_> {
    /// The field's colours on `pw × ph` screen pixels (see `Reduce`).
    fn render(&self, pw: u32, ph: u32) -> image::RgbImage {
        match self.reduce {
            Reduce::Smooth => {
                let native = self.max_render(self.width as u32, self.height as u32);
                let picture = resampled(&native);
                (picture.render)(pw, ph)
            }
            Reduce::Max => self.max_render(pw, ph),
        }
    }

    /// The field as a picture to draw.
    fn picture(&self) -> Picture<'_> {
        Picture {
            grid: (self.width as u32, self.height as u32),
            render: Box::new(|w, h| self.render(w, h)),
        }
    }

    /// Each of `pw × ph` screen pixels takes the largest finite value of the grid cells it
    /// covers (at least the nearest one); at the grid's own size, one cell each.
    fn max_render(&self, pw: u32, ph: u32) -> image::RgbImage {
        let (lo, hi) = self.range;
        let span = if hi > lo { hi - lo } else { 1.0 };
        let cells = |i: u32, n: usize, p: u32| {
            let a = i as usize * n / p as usize;
            a..((i as usize + 1) * n / p as usize).max(a + 1)
        };
        image::RgbImage::from_fn(pw, ph, |x, y| {
            let cols = cells(x, self.width, pw);
            let v = cells(y, self.height, ph)
                .flat_map(|r| cols.clone().map(move |c| r * self.width + c))
                .map(|i| self.values[i] as f64)
                .filter(|v| v.is_finite())
                .fold(f64::NEG_INFINITY, f64::max);
            image::Rgb(self.map.rgb((v - lo) / span))
        })
    }
}

/// An image to draw: its own pixel grid, and how it renders on a given number of screen pixels.
pub struct Picture<'a> {
    pub grid: (u32, u32),
    pub render: Box<dyn Fn(u32, u32) -> image::RgbImage + 'a>,
}

/// An 8-bit image as a picture: antialiased (triangle filter) where it shrinks, nearest pixel
/// where it grows, so that pixels stay sharp.
fn resampled(img: &image::RgbImage) -> Picture<'_> {
    Picture {
        grid: img.dimensions(),
        render: Box::new(move |pw, ph| {
            let filter = if pw < img.width() {
                image::imageops::FilterType::Triangle
            } else {
                image::imageops::FilterType::Nearest
            };
            image::imageops::resize(img, pw, ph, filter)
        }),
    }
}

/// The on-screen size of an image of `grid` pixels in `room` screen pixels, the data extent's
/// height/width being `aspect`: the largest size with that aspect, or a whole multiple of the
/// grid (every image pixel the same number of screen pixels) where one fills 3/4 of it.
fn screen_size(grid: (u32, u32), room: (u32, u32), aspect: f64) -> (u32, u32) {
    let (w, h) = (room.0 as f64, room.1 as f64);
    let (w, h) = if h >= w * aspect {
        (w, w * aspect)
    } else {
        (h / aspect, h)
    };
    let k = (room.0 / grid.0.max(1)).min(room.1 / grid.1.max(1));
    if k >= 1 && (k * grid.0) as f64 >= 0.75 * w {
        (k * grid.0, k * grid.1)
    } else {
        (w.max(1.0) as u32, h.max(1.0) as u32)
    }
}

/// The side, in screen pixels, that a panel gives the longer side of an `n`-pixel image
/// (`screen_size` in 440 pixels).
fn display_side(n: usize) -> u32 {
    let n = n.max(1) as u32;
    screen_size((n, n), (440, 440), 1.0).0
}

/// The height a title in a `font`-pixel font takes (a little more than plotters' `titled`).
fn title_height(font: u32) -> u32 {
    font * 3 / 2 + 10
}

/// The canvas size of an image panel for a `w × h` image: the image at `display_side`, its
/// title, margins and label areas, and `extra` pixels beside it (a colour bar).
fn panel_size((w, h): (usize, usize), extra: u32) -> (u32, u32) {
    let m = w.max(h).max(1);
    let side = display_side(m);
    (
        side * w as u32 / m as u32 + PANEL.y_labels + 2 * PANEL.margin + 4 + extra,
        side * h as u32 / m as u32
            + PANEL.x_labels
            + 2 * PANEL.margin
            + 4
            + title_height(PANEL.title),
    )
}

/// The data extent of an image's axes (x left to right, y top to bottom) and their labels.
pub struct Axes {
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub x_label: String,
    pub y_label: String,
}

impl Axes {
    /// A `w × h` image in its own pixels (`unit`: "pixels", "mirrors"); pixel (i, j) spans
    /// [i, i + 1) × [j, j + 1).
    pub fn pixels(w: usize, h: usize, unit: &str) -> Axes {
        Axes {
            x: (0.0, w as f64),
            y: (0.0, h as f64),
            x_label: format!("x ({unit})"),
            y_label: format!("y ({unit})"),
        }
    }

    /// A centred `w × h` spectrum (column i is bin i − w/2): frequencies in cycles per `unit`.
    pub fn frequency(w: usize, h: usize, unit: &str) -> Axes {
        let ext = |n: usize| {
            let c = (n / 2) as f64 + 0.5;
            (-c / n as f64, (n as f64 - c) / n as f64)
        };
        Axes {
            x: ext(w),
            y: ext(h),
            x_label: format!("fx (cycles/{unit})"),
            y_label: format!("fy (cycles/{unit})"),
        }
    }
}

/// An image panel's layout in pixels.
struct Layout {
    margin: u32,
    x_labels: u32,
    y_labels: u32,
    /// The colour bar with its tick labels and unit.
    bar: u32,
    /// The title's font size.
    title: u32,
}

const PANEL: Layout = Layout {
    margin: 8,
    x_labels: 42,
    y_labels: 58,
    bar: 84,
    title: 17,
};

/// Draw `picture`, rendered at the plot's pixel size, on `axes` in `area` under `title`,
/// with square data units, and number the `marks` (data coordinates) 1, 2, … in the line
/// plots' series colours. Returns the image's pixel rectangle on the canvas (x, y ranges).
pub fn draw_image(
    area: &Canvas,
    title: &str,
    picture: &Picture,
    axes: &Axes,
    marks: &[(f64, f64)],
) -> Draw<(Range<i32>, Range<i32>)> {
    let area = area
        .titled(title, ("sans-serif", PANEL.title))
        .map_err(show)?;
    let (aw, ah) = area.dim_in_pixel();
    let room = (
        aw.saturating_sub(2 * PANEL.margin + PANEL.y_labels),
        ah.saturating_sub(2 * PANEL.margin + PANEL.x_labels),
    );
    let aspect = (axes.y.1 - axes.y.0) / (axes.x.1 - axes.x.0);
    let (pw, ph) = screen_size(picture.grid, room, aspect);
    let area = area.shrink(
        (0, 0),
        (
            pw + 2 * PANEL.margin + PANEL.y_labels,
            ph + 2 * PANEL.margin + PANEL.x_labels,
        ),
    );
    let mut chart = ChartBuilder::on(&area)
        .margin(PANEL.margin)
        .x_label_area_size(PANEL.x_labels)
        .y_label_area_size(PANEL.y_labels)
        .build_cartesian_2d(axes.x.0..axes.x.1, axes.y.1..axes.y.0)
        .map_err(show)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(axes.x_label.as_str())
        .y_desc(axes.y_label.as_str())
        .x_label_formatter(&|v| tick_label(*v, axes.x.1 - axes.x.0))
        .y_label_formatter(&|v| tick_label(*v, axes.y.1 - axes.y.0))
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(show)?;
    let (pw, ph) = chart.plotting_area().dim_in_pixel();
    let bitmap = BitMapElement::with_owned_buffer(
        (axes.x.0, axes.y.0),
        (pw, ph),
        (picture.render)(pw, ph).into_raw(),
    )
    .ok_or("image buffer of the wrong size")?;
    chart.draw_series(std::iter::once(bitmap)).map_err(show)?;
    for (k, &p) in marks.iter().enumerate() {
        let c = series_color(k);
        let number = ("sans-serif", 15).into_font().color(&c);
        chart
            .draw_series(std::iter::once(
                EmptyElement::at(p)
                    + Circle::new((0, 0), 7, WHITE.stroke_width(5))
                    + Circle::new((0, 0), 7, c.stroke_width(3))
                    + Rectangle::new([(6, -28), (18, -7)], WHITE.mix(0.85).filled())
                    + Text::new(format!("{}", k + 1), (8, -24), number),
            ))
            .map_err(show)?;
    }
    Ok(chart.plotting_area().get_pixel_range())
}

/// A vertical colour bar for `field`'s range beside an image whose pixel rows are `rows`, at
/// the left of `area`; its axis on the right labelled with the field's unit.
fn draw_colorbar(area: &Canvas, field: &Field, rows: &Range<i32>) -> Draw {
    let (_, top) = area.get_base_pixel();
    let (_, ah) = area.dim_in_pixel();
    let (lo, hi) = field.range;
    let mut chart = ChartBuilder::on(area)
        .margin_top((rows.start - top).max(0) as u32)
        .margin_bottom((top + ah as i32 - rows.end).max(0) as u32)
        .margin_left(6)
        .right_y_label_area_size(PANEL.bar - 24)
        .build_cartesian_2d(0.0..1.0, lo..hi)
        .map_err(show)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(field.unit.as_str())
        .y_labels(6)
        .y_label_formatter(&|v| tick_label(*v, hi - lo))
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(show)?;
    const STEPS: usize = 128;
    let at = |i: usize| lo + (hi - lo) * i as f64 / STEPS as f64;
    chart
        .draw_series((0..STEPS).map(|i| {
            let [r, g, b] = field.map.rgb((i as f64 + 0.5) / STEPS as f64);
            Rectangle::new([(0.0, at(i)), (1.0, at(i + 1))], RGBColor(r, g, b).filled())
        }))
        .map_err(show)?;
    Ok(())
}

/// `field` on `axes` in `area` under `title`, its colour bar to the right of the image.
pub fn draw_field(
    area: &Canvas,
    title: &str,
    field: &Field,
    axes: &Axes,
    marks: &[(f64, f64)],
) -> Draw {
    let (aw, ah) = area.dim_in_pixel();
    let left = area
        .clone()
        .shrink((0, 0), (aw.saturating_sub(PANEL.bar), ah));
    let (cols, rows) = draw_image(&left, title, &field.picture(), axes, marks)?;
    let (x0, _) = area.get_base_pixel();
    let bar = area
        .clone()
        .shrink(((cols.end - x0).max(0) as u32, 0), (PANEL.bar, ah));
    draw_colorbar(&bar, field, &rows)
}

/// Per pixel, the RMS over bands of `est − truth`, in the cubes' unit.
pub fn pixel_rmse(truth: &Cube, est: &Cube) -> Result<Vec<f32>> {
    if (truth.width, truth.height, truth.planes) != (est.width, est.height, est.planes) {
        return Err(Error::Shape(format!(
            "truth {} against reconstruction {}",
            truth.size_text(),
            est.size_text()
        )));
    }
    let n = truth.pixels();
    Ok((0..n)
        .map(|p| {
            let ss: f64 = (0..truth.planes)
                .map(|b| (est.data[b * n + p] as f64 - truth.data[b * n + p] as f64).powi(2))
                .sum();
            (ss / truth.planes.max(1) as f64).sqrt() as f32
        })
        .collect())
}

/// What the comparison panel shows: the cubes, their sRGB previews (`Colorimetry::preview`) and
/// the marked pixels.
pub struct Comparison<'a> {
    pub truth: Option<(&'a Cube, &'a image::RgbImage)>,
    pub est: (&'a Cube, &'a image::RgbImage),
    /// How the colours were made, e.g. "reflectance under illuminants/D65".
    pub lighting: String,
    /// The cube's quantity and unit, e.g. "reflectance" or "radiance, scene units".
    pub unit: String,
    pub pixels: &'a [(usize, usize)],
}

/// Truth, reconstruction and the per-pixel spectral RMSE side by side, the marked pixels
/// numbered on each; without a truth, the reconstruction alone, saying so.
pub fn comparison_png(path: &Path, c: &Comparison) -> Result<()> {
    let (est, est_rgb) = c.est;
    let (w, h) = (est.width, est.height);
    let axes = Axes::pixels(w, h, "pixels");
    let marks: Vec<(f64, f64)> = c
        .pixels
        .iter()
        .map(|&(x, y)| (x as f64 + 0.5, y as f64 + 0.5))
        .collect();
    let heading = format!(
        "sRGB from CIE 1931 2° XYZ (D65 white) of the {}; numbers: the pixels of spectra.png",
        c.lighting
    );
    const HEADING: u32 = 15;
    let (pw, ph) = panel_size((w, h), 0);
    let ch = ph + title_height(HEADING);
    let Some(truth) = c.truth else {
        // The heading needs 640 px; a narrower panel is centred under it.
        let width = pw.max(640);
        return render_png(path, (width, ch), |root| {
            let root = root.titled(&heading, ("sans-serif", 12)).map_err(show)?;
            let (_, rest) = root.split_horizontally((width - pw) / 2);
            let (area, _) = rest.split_horizontally(pw);
            let t = "reconstruction (no truth given: no error map)";
            draw_image(&area, t, &resampled(est_rgb), &axes, &marks).map(|_| ())
        });
    };
    let (truth, truth_rgb) = truth;
    let err = pixel_rmse(truth, est)?;
    let field = Field {
        values: &err,
        width: w,
        height: h,
        map: ColorMap::Viridis,
        range: (0.0, finite_range(&err).1.max(f64::MIN_POSITIVE)),
        reduce: Reduce::Smooth,
        unit: format!("spectral RMSE ({})", c.unit),
    };
    render_png(path, (3 * pw + PANEL.bar, ch), |root| {
        let root = root
            .titled(&heading, ("sans-serif", HEADING))
            .map_err(show)?;
        let (a, rest) = root.split_horizontally(pw);
        let (b, e) = rest.split_horizontally(pw);
        draw_image(&a, "truth", &resampled(truth_rgb), &axes, &marks)?;
        draw_image(&b, "reconstruction", &resampled(est_rgb), &axes, &marks)?;
        draw_field(&e, "per-pixel error: RMS over bands", &field, &axes, &marks)
    })
}

/// The figures of a reconstruction `est`: sRGB previews (cube_rgb.png, truth_rgb.png), the
/// comparison panel (comparison.png) and spectra.png at the pixels marked on the panel;
/// without a truth, the reconstruction alone.
pub fn write_figures(
    exp: &Experiment,
    lib: &Library,
    truth: Option<&Cube>,
    est: &Cube,
    files: &OutputSet,
) -> Result<()> {
    use specmux_twin::scene::Quantity;
    let grid = exp.scene.grid(&exp.file)?;
    let (light, lighting, unit, y_label) = match exp.scene.quantity {
        Quantity::Reflectance => (
            Some(exp.curve(lib, &exp.scene.illuminant)?),
            format!("reflectance under {}", exp.scene.illuminant),
            "reflectance",
            "reflectance (1 = white)",
        ),
        Quantity::Radiance => (
            None,
            "radiance".to_string(),
            "radiance, scene units",
            "spectral radiance (scene units)",
        ),
    };
    let col = Colorimetry::new(lib, &grid, light.as_ref())?;
    let reference = truth.unwrap_or(est);
    let exposure = if light.is_some() {
        1.0
    } else {
        1.0 / f64::from(reference.max().max(f32::MIN_POSITIVE))
    };
    let truth_rgb = truth.map(|t| col.preview(t, exposure)).transpose()?;
    let est_rgb = col.preview(est, exposure)?;
    let previews = || -> Result<()> {
        for (name, img) in [
            ("truth_rgb.png", truth_rgb.as_ref()),
            ("cube_rgb.png", Some(&est_rgb)),
        ] {
            if let Some(img) = img {
                specmux_io::png::write_png(&files.path(name), img)?;
            }
        }
        Ok(())
    };
    let pixels = crate::plot::distinct_pixels(reference, 4);
    let panel = Comparison {
        truth: truth.zip(truth_rgb.as_ref()),
        est: (est, &est_rgb),
        lighting,
        unit: unit.into(),
        pixels: &pixels,
    };
    // Each PNG's deflate runs on one thread: the previews beside the panel and the plot.
    let (written, plotted) = rayon::join(previews, || {
        comparison_png(&files.path("comparison.png"), &panel)?;
        let spectra = files.path("spectra.png");
        crate::plot::spectra_plot(&spectra, &grid, (truth, est), &pixels, y_label)
    });
    written.and(plotted)
}

/// One channel's pattern figure: the pattern on the DMD (mirrors) and on the sensor (pixels),
/// each beside its centred Fourier plane as log10(1 + |FFT|).
pub fn pattern_png(
    path: &Path,
    title: &str,
    display: (&[f32], usize, usize),
    imaged: (&[f32], usize, usize),
) -> Result<()> {
    let spectra = [display, imaged].map(|(v, w, h)| log_spectrum(v, w, h));
    let cells = [display, imaged].map(|(_, w, h)| panel_size((w, h), PANEL.bar));
    let cell = (cells[0].0.max(cells[1].0), cells[0].1.max(cells[1].1));
    let size = (2 * cell.0, 2 * cell.1 + title_height(20));
    render_png(path, size, |root| {
        let root = root.titled(title, ("sans-serif", 20)).map_err(show)?;
        let (top, bottom) = root.split_vertically(cell.1);
        for (row, (area, (v, w, h))) in [top, bottom].iter().zip([display, imaged]).enumerate() {
            let (plane, unit) = [
                ("displayed on the DMD", "mirror"),
                ("imaged on the sensor", "pixel"),
            ][row];
            let pattern = Field {
                values: v,
                width: w,
                height: h,
                map: ColorMap::Grey,
                range: finite_range(v),
                reduce: Reduce::Smooth,
                unit: "intensity (relative)".into(),
            };
            let spectrum = Field {
                values: &spectra[row],
                range: finite_range(&spectra[row]),
                map: ColorMap::Viridis,
                reduce: Reduce::Max,
                unit: "log10(1 + |FFT|)".into(),
                ..pattern
            };
            let (left, right) = area.split_horizontally(cell.0);
            let pixels = Axes::pixels(w, h, &format!("{unit}s"));
            draw_field(&left, &format!("pattern {plane}"), &pattern, &pixels, &[])?;
            let freq = Axes::frequency(w, h, unit);
            let t = "its Fourier plane (DC at the centre)";
            draw_field(&right, t, &spectrum, &freq, &[])?;
        }
        Ok(())
    })
}

/// log10(1 + |FFT|) of a `w × h` image, DC at the centre (column i is bin i − w/2).
fn log_spectrum(v: &[f32], w: usize, h: usize) -> Vec<f32> {
    let spec = specmux_core::fft::Fft2::new(w, h).forward(v);
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let (kx, ky) = (x as i64 - (w / 2) as i64, y as i64 - (h / 2) as i64);
            out[y * w + x] = spec.at(kx, ky).norm().ln_1p() / std::f32::consts::LN_10;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Relative luminance of an 8-bit sRGB colour (Rec. 709 weights on the encoded values).
    fn luma([r, g, b]: [u8; 3]) -> f64 {
        0.2126 * r as f64 + 0.7152 * g as f64 + 0.0722 * b as f64
    }

    #[test]
    fn colour_maps_rise_in_lightness_and_clamp() {
        for map in [ColorMap::Grey, ColorMap::Viridis] {
            let l: Vec<f64> = (0..=100).map(|i| luma(map.rgb(i as f64 / 100.0))).collect();
            assert!(l.windows(2).all(|p| p[1] > p[0]), "{map:?}: {l:?}");
            assert_eq!(map.rgb(-3.0), map.rgb(0.0));
            assert_eq!(map.rgb(7.0), map.rgb(1.0));
            assert_eq!(map.rgb(f64::NAN), map.rgb(0.0));
        }
        assert_eq!(ColorMap::Viridis.rgb(1.0), [0xfd, 0xe7, 0x25]);
        assert_eq!(ColorMap::Grey.rgb(0.5), [128; 3]);
    }

    #[test]
    fn frequency_axes_put_dc_at_the_centre_of_its_column() {
        let a = Axes::frequency(256, 64, "pixel");
        let bin = 1.0 / 256.0;
        // Column 128 (DC) spans [-0.5, 0.5) bins; column 0 is bin -128 = -0.5 cycles/pixel.
        assert!((a.x.0 - (-128.5 * bin)).abs() < 1e-12 && (a.x.1 - 127.5 * bin).abs() < 1e-12);
        assert!((a.y.0 + 32.5 / 64.0).abs() < 1e-12, "{:?}", a.y);
        assert_eq!(a.x_label, "fx (cycles/pixel)");
    }

    #[test]
    fn pixel_rmse_is_the_rms_over_bands() {
        let truth = Cube::zeros(2, 1, 2);
        let mut est = Cube::zeros(2, 1, 2);
        // Pixel 0: errors 3 and 4 → sqrt((9 + 16) / 2); pixel 1: no error.
        est.data = vec![3.0, 0.0, 4.0, 0.0];
        let e = pixel_rmse(&truth, &est).unwrap();
        assert!(
            (e[0] - (12.5f32).sqrt()).abs() < 1e-6 && e[1] == 0.0,
            "{e:?}"
        );
        assert!(pixel_rmse(&truth, &Cube::zeros(1, 2, 2)).is_err());
    }

    #[test]
    fn ranges_skip_non_finite_values_and_widen_a_constant() {
        assert_eq!(
            finite_range(&[2.0, f32::NAN, -1.0, f32::INFINITY]),
            (-1.0, 2.0)
        );
        assert_eq!(finite_range(&[3.0, 3.0]), (2.5, 3.5));
        assert_eq!(finite_range(&[]), (0.0, 1.0));
    }

    #[test]
    fn shrinking_by_max_keeps_a_one_cell_peak_that_smoothing_spreads() {
        let mut v = vec![0.0f32; 64];
        v[3 * 8 + 5] = 1.0;
        let field = |reduce| Field {
            values: &v,
            width: 8,
            height: 8,
            map: ColorMap::Grey,
            range: (0.0, 1.0),
            reduce,
            unit: String::new(),
        };
        let max = field(Reduce::Max).render(4, 4);
        assert_eq!(max.get_pixel(2, 1).0, [255; 3]);
        assert_eq!(max.pixels().filter(|p| p.0 != [0; 3]).count(), 1);
        let smooth = field(Reduce::Smooth).render(4, 4);
        assert!(
            smooth.get_pixel(2, 1).0[0] < 200,
            "{:?}",
            smooth.get_pixel(2, 1)
        );
        // At the grid's own size both show every cell as it is.
        assert_eq!(
            field(Reduce::Smooth).render(8, 8).get_pixel(5, 3).0,
            [255; 3]
        );
    }

    #[test]
    fn images_take_whole_multiples_of_their_pixels_where_those_fill_the_room() {
        // 128 px in 440: ×3 = 384 fills more than 3/4 of 440.
        assert_eq!(screen_size((128, 128), (440, 500), 1.0), (384, 384));
        // 256 px in 440: ×1 would leave 42 % empty, so the image fills the room.
        assert_eq!(screen_size((256, 256), (440, 500), 1.0), (440, 440));
        // Larger than the room: shrunk to fit with the data's aspect.
        assert_eq!(screen_size((768, 384), (440, 440), 0.5), (440, 220));
        assert_eq!(screen_size((100, 50), (450, 300), 0.5), (400, 200));
        assert_eq!(display_side(256), 440);
        assert_eq!(display_side(64), 384);
    }
}
