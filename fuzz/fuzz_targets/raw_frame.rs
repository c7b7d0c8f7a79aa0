//! Any bytes as a camera frame in raw DN (a 16-bit greyscale PNG or TIFF): a frame whose size
//! matches its data, or a one-line error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    match specmux_io::frame::grey16_from_bytes(data, std::path::Path::new("fuzz.png")) {
        Ok(frame) => assert_eq!(frame.data.len(), frame.width * frame.height),
        Err(e) => assert_eq!(e.to_string().lines().count(), 1, "{e}"),
    }
});
