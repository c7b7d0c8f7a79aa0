//! The photon-transfer plot of an EMVA 1288 measurement (twin::sensor::ptc), and its raw
//! frames written as an EMVA 1288 descriptor file + 16-bit PNGs for the reference code.

use crate::plot::{render_png, show, tick_label};
use plotters::prelude::*;
use specmux_core::{Cube, Error, Result};
use specmux_twin::sensor::{PtcFrames, PtcResult};
use std::fmt::Write as _;
use std::path::Path;

/// Quantum efficiency written into the EMVA descriptor: the twin's photon-transfer measurement
/// works in photo-electrons, so photons per pixel are stated as μ_e/η with this η; an outside
/// analysis must find it back from the frames.
pub const EMVA_DESCRIPTOR_QE: f64 = 0.5;

/// Exposure time written into the descriptor (ns): one exposure, the light varied (EMVA 1288
/// allows either series).
const EMVA_EXPOSURE_NS: f64 = 1e6;

/// Write `frames` into `dir` as the EMVA 1288 reference code reads them: `emva1288.txt` (the
/// descriptor: `n bits width height`, `d`/`b` lines with their images) and one 16-bit PNG per
/// frame. Pairs are the temporal data; the L-frame dark and flat sequences the spatial data.
pub fn write_emva_dataset(dir: &Path, frames: &PtcFrames, bits: u32) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let (w, h) = (frames.pairs[0].1[0].width, frames.pairs[0].1[0].height);
    let mut text = format!(
        "# specmux photon-transfer frames; photons = electrons / {EMVA_DESCRIPTOR_QE} (stated QE)\n\
         v 3.1\nn {bits} {w} {h}\n"
    );
    let mut series = |head: String, name: &str, images: &[Cube]| -> Result<()> {
        text.push_str(&head);
        for (k, img) in images.iter().enumerate() {
            let file = format!("{name}-{k:02}.png");
            specmux_io::png::dn_png16(&dir.join(&file), img)?;
            let _ = writeln!(text, "i {file}");
        }
        Ok(())
    };
    for (i, (level, pair)) in frames.pairs.iter().enumerate() {
        let head = match i {
            0 => format!("d {EMVA_EXPOSURE_NS}\n"),
            _ => format!("b {EMVA_EXPOSURE_NS} {}\n", level / EMVA_DESCRIPTOR_QE),
        };
        series(head, &format!("pair{i:02}"), pair)?;
    }
    series(
        format!("d {EMVA_EXPOSURE_NS}\n"),
        "dark-seq",
        &frames.dark_sequence,
    )?;
    let (half, flats) = &frames.flat_sequence;
    let head = format!("b {EMVA_EXPOSURE_NS} {}\n", half / EMVA_DESCRIPTOR_QE);
    series(head, "flat-seq", flats)?;
    specmux_io::atomic::write_bytes(&dir.join("emva1288.txt"), text.as_bytes())
}

/// Write the photon-transfer curve as a PNG: σ_y² − σ_y.dark² against μ_y − μ_y.dark (linear
/// axes, as in EMVA 1288 data sheets), the fitted line over its range and the saturation.
pub fn plot_ptc(result: &PtcResult, path: &Path) -> Result<()> {
    let pts: Vec<(f64, f64)> = result
        .points
        .iter()
        .map(|p| {
            (
                p.mean_dn - result.dark_mean_dn,
                p.variance_dn2 - result.dark_variance_dn2,
            )
        })
        .collect();
    let x_max = pts.iter().map(|p| p.0).fold(1.0, f64::max) * 1.05;
    let y_max = pts.iter().map(|p| p.1).fold(1.0, f64::max) * 1.1;
    let y_min = pts.iter().map(|p| p.1).fold(0.0, f64::min);
    render_png(path, (900, 600), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!(
                    "Photon transfer: K = {:.4} ± {:.4} DN/e⁻, σ_d = {:.2} e⁻, μ_e.sat = {:.0} e⁻",
                    result.k_dn_per_e,
                    result.k_stderr_dn_per_e,
                    result.read_noise_e,
                    result.full_well_e
                ),
                ("sans-serif", 20),
            )
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x_max, y_min..y_max)
            .map_err(show)?;
        chart
            .configure_mesh()
            .x_desc("μ_y − μ_y.dark (DN)")
            .y_desc("σ_y² − σ_y.dark² (DN²)")
            .x_label_formatter(&|v| tick_label(*v, x_max))
            .y_label_formatter(&|v| tick_label(*v, y_max - y_min))
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(show)?;
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, BLUE.filled())))
            .map_err(show)?
            .label("measured pairs")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLUE.filled()));
        let line = |x: f64| result.fit_offset_dn2 + result.k_dn_per_e * x;
        let x_sat = result.saturation_mean_dn - result.dark_mean_dn;
        let fit_end = result.fit_max_signal_dn;
        for (seg, color, label) in [
            (
                [(0.0, line(0.0)), (fit_end, line(fit_end))],
                BLACK,
                "fit (0–70 % of saturation)",
            ),
            (
                [(x_sat, y_min), (x_sat, y_max)],
                RED,
                "saturation (variance maximum)",
            ),
        ] {
            let style = color.stroke_width(2);
            chart
                .draw_series(LineSeries::new(seg, style))
                .map_err(show)?
                .label(label)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], style));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(("sans-serif", 15))
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(show)
    })
}
