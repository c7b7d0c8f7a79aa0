//! PNG images: 8-bit images and grey previews of one plane, written atomically.

use crate::atomic;
use specmux_core::{Cube, Error, Result};
use std::path::Path;

/// Encode an 8-bit image as PNG and write it; the adaptive row filter keeps figures of noisy
/// fields small (docs/ keeps its figures under 300 kB).
pub fn write_png(path: &Path, img: image::DynamicImage) -> Result<()> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    let mut bytes = Vec::new();
    let png =
        PngEncoder::new_with_quality(&mut bytes, CompressionType::Default, FilterType::Adaptive);
    img.write_with_encoder(png).map_err(|e| Error::Image {
        path: path.to_path_buf(),
        msg: e.to_string(),
    })?;
    atomic::write_bytes(path, &bytes)
}

/// A grey PNG of one plane, scaled so that its maximum is white.
pub fn plane_png(path: &Path, cube: &Cube, plane: usize) -> Result<()> {
    let p = cube.plane(plane);
    let max = p.iter().cloned().fold(0.0f32, f32::max);
    let k = if max > 0.0 { 255.0 / max } else { 0.0 };
    let px: Vec<u8> = p
        .iter()
        .map(|v| (v.max(0.0) * k).round().min(255.0) as u8)
        .collect();
    let img = image::GrayImage::from_raw(cube.width as u32, cube.height as u32, px)
        .ok_or_else(|| Error::Shape("plane size".into()))?;
    write_png(path, image::DynamicImage::ImageLuma8(img))
}
