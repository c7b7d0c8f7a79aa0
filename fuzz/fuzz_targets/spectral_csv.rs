//! Any text as a spectral CSV: a table of finite, increasing curves, or a one-line error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        match specmux_core::spectral::csv::parse(std::path::Path::new("fuzz.csv"), text) {
            Ok(t) => {
                for c in &t.curves {
                    assert!(c.values().iter().all(|v| v.is_finite()));
                    assert!(c.wavelengths().windows(2).all(|w| w[0] < w[1]));
                }
            }
            Err(e) => assert_eq!(e.to_string().lines().count(), 1, "{e}"),
        }
    }
});
