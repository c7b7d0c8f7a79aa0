//! Any bytes as an EXR file: a cube whose size matches its data, or a one-line error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match specmux_io::exr::read_bytes(data, std::path::Path::new("fuzz.exr")) {
        Ok((cube, names)) => {
            assert_eq!(cube.data.len(), cube.width * cube.height * cube.planes);
            assert_eq!(names.len(), cube.planes);
        }
        Err(e) => assert_eq!(e.to_string().lines().count(), 1, "{e}"),
    }
});
