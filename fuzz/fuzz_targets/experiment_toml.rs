//! Any text as an experiment file: parsed and validated, or refused with a one-line error.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Err(e) = specmux_twin::experiment::Experiment::from_toml(text, "fuzz.toml") {
            assert_eq!(e.to_string().lines().count(), 1, "{e}");
        }
    }
});
