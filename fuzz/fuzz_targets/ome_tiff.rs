//! Any bytes as a recording's OME-TIFF (the controller's reader of frames and calibration): pages
//! whose sizes match their data, or a one-line error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match specmux_controller::ome::parse(data, std::path::Path::new("fuzz.ome.tif")) {
        Ok((_, pages)) => {
            for p in pages {
                assert_eq!(p.data.len(), p.width * p.height);
            }
        }
        Err(e) => assert_eq!(e.to_string().lines().count(), 1, "{e}"),
    }
});
