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
        // Blocks in increasing order: the bytes do not depend on which thread compressed first.
        Encoding {
            line_order: LineOrder::Increasing,
            ..Encoding::FAST_LOSSLESS
        },
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

/// Read every channel of the first layer of an EXR file: the cube (planes in the file's
/// channel order, which is name order) and the channel names.
pub fn read(path: &Path) -> Result<(Cube, Vec<String>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    read_bytes(&bytes, path)
}

/// `read` on the bytes of an EXR file; `path` names it in errors.
pub fn read_bytes(bytes: &[u8], path: &Path) -> Result<(Cube, Vec<String>)> {
    let err = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
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

    #[test]
    fn round_trip_is_bit_exact() {
        let dir = std::env::temp_dir().join(format!("specmux-exr-{}", std::process::id()));
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
        std::fs::remove_dir_all(dir).ok();
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
