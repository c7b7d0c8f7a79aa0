//! NumPy `.npy` output (format version 1.0): a cube as a little-endian float32 array of shape
//! (planes, height, width), a one-plane frame as (height, width) — what `numpy.load` returns
//! with no conversion. Written by hand: the format is a magic string, a Python-dict header
//! padded to 64 bytes, and the raw samples.

use crate::atomic;
use specmux_core::{Cube, Result};
use std::path::Path;

/// The bytes of `cube` as an `.npy` file.
pub fn encode(cube: &Cube) -> Vec<u8> {
    let shape = if cube.planes == 1 {
        format!("({}, {})", cube.height, cube.width)
    } else {
        format!("({}, {}, {})", cube.planes, cube.height, cube.width)
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    // Magic (6) + version (2) + header length (2) + header + '\n', a multiple of 64.
    let pad = (64 - (10 + header.len() + 1) % 64) % 64;
    header.push_str(&" ".repeat(pad));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 4 * cube.data.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in &cube.data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Write `cube` as an `.npy` file, atomically.
pub fn write(path: &Path, cube: &Cube) -> Result<()> {
    atomic::write_bytes(path, &encode(cube))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The header is the one numpy writes for the same array, padded to 64 bytes, and the
    /// samples follow in C order (plane, row, column).
    #[test]
    fn header_and_samples_are_numpys() {
        let cube = Cube::from_vec(3, 2, 2, (0..12).map(|v| v as f32).collect()).unwrap();
        let b = encode(&cube);
        assert_eq!(&b[..8], b"\x93NUMPY\x01\x00");
        let n = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + n) % 64, 0);
        let h = std::str::from_utf8(&b[10..10 + n]).unwrap();
        assert!(
            h.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2, 3), }"),
            "{h}"
        );
        assert!(h.ends_with('\n'));
        let v: Vec<f32> = b[10 + n..]
            .chunks(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect();
        assert_eq!(v, cube.data);
        let frame = Cube::from_vec(3, 2, 1, vec![0.0; 6]).unwrap();
        assert!(String::from_utf8_lossy(&encode(&frame)).contains("'shape': (2, 3), }"));
    }
}
