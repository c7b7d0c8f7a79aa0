//! Camera frames and calibration frames as a user brings them: one-channel EXR (any units) or
//! 16-bit greyscale PNG or TIFF (raw DN, as camera software saves them). An 8-bit image is a
//! preview, not data: it is refused with what to pass instead.

use crate::exr;
use specmux_core::calibration::CalibrationFrames;
use specmux_core::{Cube, Error, Result};
use std::path::{Path, PathBuf};

/// True when the file holds raw DN (a 16-bit PNG or TIFF) rather than values in the twin's units.
pub fn is_raw_dn(path: &Path) -> bool {
    matches!(extension(path).as_str(), "png" | "tif" | "tiff")
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default()
}

/// One camera frame, checked finite and within the range the reconstruction takes
/// ([`Cube::frame_problem`]).
pub fn read(path: &Path) -> Result<Cube> {
    // A path that is not there is said so, whatever its extension.
    std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    let bad = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
    let frame = match extension(path).as_str() {
        "exr" => exr::read(path)?.0,
        "png" | "tif" | "tiff" => read_grey16(path)?,
        e => return Err(bad(format!("`.{e}` is not a frame format specmux reads: pass a one-channel EXR (.exr) or a 16-bit greyscale PNG or TIFF (.png, .tif)"))),
    };
    if frame.planes != 1 {
        return Err(bad(format!(
            "a frame has one channel, this file has {}",
            frame.planes
        )));
    }
    match frame.frame_problem("") {
        Some(why) => Err(bad(why)),
        None => Ok(frame),
    }
}

/// A 16-bit greyscale PNG or TIFF as DN.
fn read_grey16(path: &Path) -> Result<Cube> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    grey16_from_bytes(&bytes, path)
}

/// [`read_grey16`] over bytes in memory (`path` names them in errors): the format is sniffed
/// from the bytes, and an image over the EXR reader's sample limit is refused before decoding.
pub fn grey16_from_bytes(bytes: &[u8], path: &Path) -> Result<Cube> {
    let bad = |msg: String| Error::Image {
        path: path.to_path_buf(),
        msg,
    };
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| bad(e.to_string()))?;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(4 * exr::MAX_SAMPLES as u64);
    reader.limits(limits);
    if reader.format() == Some(image::ImageFormat::Tiff) && more_pages(bytes) {
        return Err(bad("a TIFF of several pages (a recording's frames.ome.tif?) is no single frame: pass one frame, or the recording's folder to `specmux reconstruct RECORDING_DIR`".into()));
    }
    let img = reader.decode().map_err(|e| bad(e.to_string()))?;
    let image::DynamicImage::ImageLuma16(g) = img else {
        use image::ColorType::*;
        let kind = match img.color() {
            L8 => "an 8-bit greyscale".to_string(),
            La8 | La16 => "a greyscale-with-alpha".to_string(),
            Rgb8 | Rgba8 => "an 8-bit colour".to_string(),
            Rgb16 | Rgba16 => "a 16-bit colour".to_string(),
            c => format!("a {c:?}"),
        };
        return Err(bad(format!(
            "{kind} image is a preview, not a camera frame: pass frame.exr or a 16-bit greyscale PNG or TIFF of raw DN"
        )));
    };
    let (w, h) = (g.width() as usize, g.height() as usize);
    Cube::from_vec(w, h, 1, g.into_raw().into_iter().map(f32::from).collect())
}

/// Whether a TIFF holds a page after its first (a stack, whose other pages a frame reader would
/// silently leave out); a TIFF the decoder cannot open is left to the image reader's error.
fn more_pages(bytes: &[u8]) -> bool {
    tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).is_ok_and(|d| d.more_images())
}

/// The frame `stem` in `dir` (`.exr`, else `.png`, `.tif`, `.tiff`), None when none exists.
fn find(dir: &Path, stem: &str) -> Option<PathBuf> {
    ["exr", "png", "tif", "tiff"]
        .iter()
        .map(|e| dir.join(format!("{stem}.{e}")))
        .find(|p| p.is_file())
}

/// Read a calibration folder for `n` carriers on `width`×`height` frames: `dark.exr` and
/// `flat.exr` (both or neither; without them the patterns are taken as linear) and
/// `pattern-1.exr` … `pattern-N.exr`, one per carrier in the experiment's order (a 16-bit
/// `.png` in place of any `.exr` is read too). `source` in the result names the folder.
pub fn read_calibration(
    dir: &Path,
    n: usize,
    width: usize,
    height: usize,
) -> Result<CalibrationFrames> {
    if !dir.is_dir() {
        let what = match dir.exists() {
            true => "is a file",
            false => "no such folder",
        };
        let why = format!("{what}: calibration frames are a folder of dark.exr, flat.exr and pattern-1.exr … pattern-N.exr (as `specmux simulate` writes it); a recording's calibration.ome.tif is read by `specmux reconstruct RECORDING_DIR`");
        return Err(Error::io(dir, std::io::Error::other(why)));
    }
    let missing = |stem: &str| {
        Error::io(
        dir.join(format!("{stem}.exr")),
        std::io::Error::new(std::io::ErrorKind::NotFound, "missing: a calibration folder holds dark.exr and flat.exr (or neither) and pattern-1.exr … pattern-N.exr, one per carrier"),
    )
    };
    let sized = |p: PathBuf| -> Result<Cube> {
        let f = read(&p)?;
        if (f.width, f.height) != (width, height) {
            return Err(Error::Exr {
                path: p,
                msg: format!("{}×{}, the frame is {width}×{height}", f.width, f.height),
            });
        }
        Ok(f)
    };
    let (dark, flat) = match (find(dir, "dark"), find(dir, "flat")) {
        (Some(d), Some(f)) => (Some(sized(d)?), Some(sized(f)?)),
        (None, None) => (None, None),
        (None, _) => return Err(missing("dark")),
        (_, None) => return Err(missing("flat")),
    };
    let mut patterns = Cube::zeros(width, height, n);
    for k in 0..n {
        let stem = format!("pattern-{}", k + 1);
        let p = sized(find(dir, &stem).ok_or_else(|| missing(&stem))?)?;
        patterns.plane_mut(k).copy_from_slice(&p.data);
    }
    if let Some(extra) = find(dir, &format!("pattern-{}", n + 1)) {
        return Err(Error::Exr {
            path: extra,
            msg: format!("the experiment has {n} carriers, so pattern-1 … pattern-{n} only"),
        });
    }
    Ok(CalibrationFrames::single(
        dark,
        flat,
        patterns,
        format!("files in {}", dir.display()),
    ))
}

/// Write `frames` as a calibration folder `read_calibration` reads back (EXR, one channel each;
/// with `npy`, each also as `.npy`). Linear patterns beside dark and flat frames (the oracle)
/// would read back as raw: refused.
pub fn write_calibration(dir: &Path, frames: &CalibrationFrames, npy: bool) -> Result<()> {
    if frames.patterns_linear && frames.dark.is_some() {
        return Err(Error::Shape(
            "oracle calibration frames are not captures and are not written".into(),
        ));
    }
    let write = |stem: &str, frame: &Cube| -> Result<()> {
        exr::write(&dir.join(format!("{stem}.exr")), frame, &["Y".to_string()])?;
        match npy {
            true => crate::npy::write(&dir.join(format!("{stem}.npy")), frame),
            false => Ok(()),
        }
    };
    if let (Some(d), Some(f)) = (&frames.dark, &frames.flat) {
        write("dark", d)?;
        write("flat", f)?;
    }
    for k in 0..frames.patterns.planes {
        write(&format!("pattern-{}", k + 1), &frames.patterns.extract(k))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_16_bit_tiff_reads_as_the_same_dn_as_the_png_and_8_bits_or_a_stack_are_refused() {
        let scratch = tempfile::Builder::new()
            .prefix("specmux-frame-tif-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let img =
            image::ImageBuffer::from_fn(5, 3, |x, y| image::Luma([(x * 1000 + y * 7) as u16]));
        let (tif, png) = (dir.join("f.tif"), dir.join("f.png"));
        img.save(&tif).unwrap();
        img.save(&png).unwrap();
        let (a, b) = (read(&tif).unwrap(), read(&png).unwrap());
        assert_eq!((a.width, a.height, a.planes), (5, 3, 1));
        assert_eq!(a.data, b.data);
        assert_eq!(a.data[5 + 4], 4007.0);
        assert!(is_raw_dn(&tif) && is_raw_dn(&dir.join("F.TIFF")));
        let grey8 = image::GrayImage::from_pixel(4, 4, image::Luma([9]));
        grey8.save(dir.join("g.tif")).unwrap();
        let e = read(&dir.join("g.tif")).unwrap_err().to_string();
        assert!(e.contains("g.tif") && e.contains("preview"), "{e}");
        // A stack of two 16-bit pages is no frame: refused, not read as its first page.
        let stack = dir.join("frames.ome.tif");
        let mut enc =
            tiff::encoder::TiffEncoder::new(std::fs::File::create(&stack).unwrap()).unwrap();
        for page in 0..2u16 {
            let data = vec![page; 4 * 4];
            enc.write_image::<tiff::encoder::colortype::Gray16>(4, 4, &data)
                .unwrap();
        }
        drop(enc);
        let e = read(&stack).unwrap_err().to_string();
        assert!(
            e.contains("frames.ome.tif") && e.contains("several pages"),
            "{e}"
        );
    }

    #[test]
    fn calibration_frames_are_a_folder_and_a_file_or_missing_path_says_so() {
        let scratch = tempfile::Builder::new()
            .prefix("specmux-frame-cal-")
            .tempdir()
            .unwrap();
        let file = scratch.path().join("calibration.ome.tif");
        std::fs::write(&file, "x").unwrap();
        let e = read_calibration(&file, 6, 5, 3).unwrap_err().to_string();
        assert!(
            e.contains("calibration.ome.tif: is a file") && e.contains("RECORDING_DIR"),
            "{e}"
        );
        let e = read_calibration(&scratch.path().join("none"), 6, 5, 3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("none: no such folder"), "{e}");
    }
}
