//! PNG images: 8-bit images, grey previews of one plane and 16-bit raw frames, written
//! atomically.

use crate::atomic;
use specmux_core::{Cube, Error, Result};
use std::path::Path;

/// Encode an image (8-bit RGB or grey, 16-bit grey) as PNG and write it; the adaptive row
/// filter keeps figures of noisy fields small (docs/ keeps its figures under 300 kB). It borrows
/// the image, so a caller that shows it elsewhere too need not copy it.
pub fn write_png<P>(path: &Path, img: &image::ImageBuffer<P, Vec<P::Subpixel>>) -> Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
{
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
    write_png(path, &img)
}

/// A 16-bit grey PNG of a one-plane frame of whole DN (a raw camera frame, as the EMVA 1288
/// reference code and image viewers read them); refuses a value that is not a whole DN in
/// 0–65535 rather than rounding or clamping it.
pub fn dn_png16(path: &Path, frame: &Cube) -> Result<()> {
    let fail = |msg: String| Error::Image {
        path: path.to_path_buf(),
        msg,
    };
    if frame.planes != 1 {
        return Err(fail(format!(
            "{} planes; a raw frame has one",
            frame.planes
        )));
    }
    let whole = |v: f32| v.fract() == 0.0 && (0.0..=65535.0).contains(&v);
    if let Some(i) = frame.data.iter().position(|&v| !whole(v)) {
        return Err(fail(format!(
            "value {} at pixel ({}, {}) is not a whole DN in 0–65535",
            frame.data[i],
            i % frame.width,
            i / frame.width
        )));
    }
    let px: Vec<u16> = frame.data.iter().map(|&v| v as u16).collect();
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(
        frame.width as u32,
        frame.height as u32,
        px,
    )
    .ok_or_else(|| fail("plane size".into()))?;
    write_png(path, &img)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_16_bit_frame_reads_back_exactly_and_a_fraction_is_refused() {
        let scratch = tempfile::Builder::new()
            .prefix("specmux-png16-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let path = dir.join("f.png");
        let frame = Cube::from_vec(3, 2, 1, vec![0.0, 1.0, 4095.0, 65535.0, 7.0, 300.0]).unwrap();
        dn_png16(&path, &frame).unwrap();
        let back = image::open(&path).unwrap().into_luma16();
        assert_eq!(back.into_raw(), vec![0, 1, 4095, 65535, 7, 300]);
        let bad = Cube::from_vec(2, 1, 1, vec![1.0, 2.5]).unwrap();
        let e = dn_png16(&path, &bad).unwrap_err().to_string();
        assert!(e.contains("2.5") && e.contains("(1, 0)"), "{e}");
    }
}
