//! Multichannel OpenEXR input and output of cubes. Spectral planes are named by wavelength
//! (`0400.0nm`, zero-padded so that EXR's name order is wavelength order); other planes keep
//! the names given. Samples are stored as f32 without loss, so a round trip is bit-exact.

use crate::atomic;
use exr::prelude::*;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::Cube;
use std::path::Path;

/// The EXR channel name of a band centred at `wl_nm`.
pub fn band_name(wl_nm: f64) -> String {
    format!("{wl_nm:06.1}nm")
}

/// The wavelength a channel name carries (`0400.0nm`, `400nm`, `S400`…), if any.
pub fn parse_band_name(name: &str) -> Option<f64> {
    let digits: String = name
        .chars()
        .skip_while(|c| !c.is_ascii_digit())
        .take_while(|c| c.is_ascii_digit() || *c == '.')
        .collect();
    digits.parse().ok()
}

/// Write `cube` with one EXR channel per plane, named by `names` (planes in the given order).
pub fn write(path: &Path, cube: &Cube, names: &[String]) -> Result<()> {
    if names.len() != cube.planes {
        return Err(Error::Shape(format!(
            "{} channel names for {} planes",
            names.len(),
            cube.planes
        )));
    }
    let channels: Vec<AnyChannel<FlatSamples>> = names
        .iter()
        .enumerate()
        .map(|(k, n)| AnyChannel::new(n.as_str(), FlatSamples::F32(cube.plane(k).to_vec())))
        .collect();
    let layer = Layer::new(
        (cube.width, cube.height),
        LayerAttributes::default(),
        // Uncompressed: run-length coding saved 0.01–0.4 % on these float planes and took a
        // third of `simulate`'s writing time (docs/speed.md, "Writing the files").
        Encoding::UNCOMPRESSED,
        AnyChannels::sort(channels.into()),
    );
    let image = Image::from_layer(layer);
    atomic::write_with(path, |w| {
        image
            .write()
            .to_buffered(w)
            .map_err(|e| std::io::Error::other(e.to_string()))
    })
}

/// "pixel (x, y) of channel `name` is v" for the first value of a cube read with channel
/// `names` that `bad` picks (a NaN, a negative radiance), for an error naming where it is.
pub fn first_value(cube: &Cube, names: &[String], bad: impl Fn(f32) -> bool) -> Option<String> {
    let p = cube.data.iter().position(|&v| bad(v))?;
    let (k, x, y) = cube.place(p);
    let name = names.get(k).map_or(k.to_string(), |s| s.clone());
    Some(format!(
        "pixel ({x}, {y}) of channel `{name}` is {}",
        cube.data[p]
    ))
}

/// Read every channel of the first layer of an EXR file: the cube (planes in the file's
/// channel order, which is name order) and the channel names.
pub fn read(path: &Path) -> Result<(Cube, Vec<String>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_bytes(&bytes, path)
}

/// Width, height and channel names (in the file's order) of an EXR file's first layer, read
/// from its header alone.
pub fn header(path: &Path) -> Result<(usize, usize, Vec<String>)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let err = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
    let meta = exr::meta::MetaData::read_from_buffered(std::io::BufReader::new(file), false)
        .map_err(|e| err(e.to_string()))?;
    let h = meta.headers.first().ok_or_else(|| err("no layer".into()))?;
    let names = h.channels.list.iter().map(|c| c.name.to_string()).collect();
    Ok((h.layer_size.width(), h.layer_size.height(), names))
}

/// The most f32 samples (width × height × channels, over all layers) a file may declare: 1 GiB
/// of data, 4× an 8192 × 8192 × 4 frame and 13× the prototype's 768 × 768 × 31 cube. A header
/// that claims more is refused before anything is allocated for it.
pub const MAX_SAMPLES: usize = 1 << 28;

/// Read only the headers and refuse a file whose layers would need more than `MAX_SAMPLES`.
fn check_declared_size(bytes: &[u8], path: &Path) -> Result<()> {
    let err = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
    let meta = exr::meta::MetaData::read_from_buffered(std::io::Cursor::new(bytes), false)
        .map_err(|e| err(e.to_string()))?;
    let samples = meta.headers.iter().try_fold(0usize, |acc, h| {
        let (w, h2, c) = (
            h.layer_size.width(),
            h.layer_size.height(),
            h.channels.list.len(),
        );
        w.checked_mul(h2)?.checked_mul(c)?.checked_add(acc)
    });
    match samples {
        Some(n) if n <= MAX_SAMPLES => Ok(()),
        _ => Err(err(format!(
            "its header declares {} samples, more than {MAX_SAMPLES} (a corrupt or foreign file?)",
            samples.map_or("more than 2^64".into(), |n| n.to_string())
        ))),
    }
}

/// `read` on the bytes of an EXR file; `path` names it in errors.
pub fn read_bytes(bytes: &[u8], path: &Path) -> Result<(Cube, Vec<String>)> {
    let err = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
    check_declared_size(bytes, path)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_buffered(std::io::Cursor::new(bytes))
        .map_err(|e| err(e.to_string()))?;
    let layer = image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let mut names = Vec::new();
    let mut data = Vec::with_capacity(w * h * layer.channel_data.list.len());
    for ch in &layer.channel_data.list {
        names.push(ch.name.to_string());
        data.extend(ch.sample_data.values_as_f32());
    }
    let cube = Cube::from_vec(w, h, names.len(), data)?;
    Ok((cube, names))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The file cargo-fuzz found (`fuzz/`, target exr_frame): a header declaring a layer too
    /// large to allocate aborted the process; it is now refused by the size check.
    #[test]
    fn a_header_declaring_a_huge_layer_is_refused_not_allocated() {
        let bytes = include_bytes!("../tests/fuzz-exr-oom.exr");
        let e = read_bytes(bytes, Path::new("crash.exr"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("crash.exr") && e.contains("samples"), "{e}");
        assert_eq!(e.lines().count(), 1);
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let scratch = tempfile::Builder::new()
            .prefix("specmux-exr-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let path = dir.join("c.exr");
        let mut cube = Cube::zeros(5, 3, 3);
        for (i, v) in cube.data.iter_mut().enumerate() {
            *v = (i as f32).sqrt() * 1.000_001 - 2.5 + f32::EPSILON * i as f32;
        }
        let names: Vec<String> = [400.0, 410.0, 420.0]
            .iter()
            .map(|&w| band_name(w))
            .collect();
        write(&path, &cube, &names).unwrap();
        let (back, back_names) = read(&path).unwrap();
        assert_eq!(back_names, names);
        assert_eq!(
            back.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            cube.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }

    #[test]
    fn band_names_sort_by_wavelength_and_parse_back() {
        assert_eq!(band_name(400.0), "0400.0nm");
        assert!(band_name(950.0) < band_name(1000.0));
        assert_eq!(parse_band_name("0412.5nm"), Some(412.5));
        assert_eq!(parse_band_name("S07"), Some(7.0));
        assert_eq!(parse_band_name("Y"), None);
    }
}
