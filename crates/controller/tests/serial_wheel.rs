//! The serial wheel backend against a simulated motor controller on a pseudo-terminal.
#![cfg(feature = "serial-wheel")]

use specmux_controller::devices::ColorWheel;
use specmux_controller::real::serial_wheel::{parse_status, SerialWheel};
use specmux_controller::Error;
use std::fs::File;
use std::io::{BufRead, BufReader, Write};
use std::os::fd::FromRawFd;
use std::path::PathBuf;

/// A pseudo-terminal: the master (the simulated controller's end) and the slave's path.
fn pty() -> (File, PathBuf) {
    // SAFETY: standard pty allocation; the descriptor is handed to a File that owns it.
    unsafe {
        let fd = libc::posix_openpt(libc::O_RDWR | libc::O_NOCTTY);
        assert!(fd >= 0 && libc::grantpt(fd) == 0 && libc::unlockpt(fd) == 0);
        let mut name = [0 as libc::c_char; 128];
        assert_eq!(libc::ptsname_r(fd, name.as_mut_ptr(), name.len()), 0);
        let path = std::ffi::CStr::from_ptr(name.as_ptr())
            .to_string_lossy()
            .into_owned();
        (File::from_raw_fd(fd), PathBuf::from(path))
    }
}

/// The motor controller: locks on the third status query after START; answers nothing after
/// `answers` lines.
fn controller(master: File, answers: usize) -> std::thread::JoinHandle<Vec<String>> {
    std::thread::spawn(move || {
        let mut out = master.try_clone().unwrap();
        let mut seen = Vec::new();
        let (mut speed, mut spinning, mut asks) = (0.0f64, false, 0);
        for line in BufReader::new(master).lines() {
            let Ok(line) = line else { break };
            seen.push(line.clone());
            if seen.len() > answers {
                continue;
            }
            let reply = match line.split_whitespace().collect::<Vec<_>>().as_slice() {
                ["SPEED", v] => match v.parse::<f64>() {
                    Ok(v) if v <= 2000.0 => {
                        speed = v;
                        "OK".to_string()
                    }
                    _ => format!("ERR speed {v} above 2000 rev/s"),
                },
                ["START"] => {
                    spinning = true;
                    "OK".into()
                }
                ["STOP"] => {
                    spinning = false;
                    "OK".into()
                }
                ["STATUS?"] => {
                    asks += 1;
                    let locked = spinning && asks >= 3;
                    let measured = if spinning { speed } else { 0.0 };
                    format!(
                        "STATUS {} {speed} {measured} {} {}",
                        spinning as u8,
                        locked as u8,
                        1000 * asks
                    )
                }
                _ => "ERR unknown command".into(),
            };
            if writeln!(out, "{reply}").is_err() {
                break;
            }
        }
        seen
    })
}

#[test]
fn drives_the_wheel_over_the_line_protocol() {
    let (master, path) = pty();
    let device = controller(master, usize::MAX);
    let mut wheel = SerialWheel::open(&path).unwrap();
    wheel.set_speed_hz(1000.0).unwrap();
    let err = wheel.set_speed_hz(5000.0).unwrap_err().to_string();
    assert_eq!(err, "wheel: SPEED 5000: speed 5000 above 2000 rev/s");
    wheel.start().unwrap();
    let s = wheel.wait_for_lock(2.0).unwrap();
    assert!(
        s.locked && s.spinning && s.target_hz == 1000.0 && s.index_pulses == 3000,
        "{s:?}"
    );
    wheel.stop().unwrap();
    assert!(!wheel.status().unwrap().spinning);
    let log: Vec<String> = wheel.events().into_iter().map(|e| e.what).collect();
    drop(wheel);
    let seen = device.join().unwrap();
    assert_eq!(seen, log, "the device saw exactly the commands logged");
    assert_eq!(&seen[..3], ["SPEED 1000", "SPEED 5000", "START"]);
}

#[test]
fn a_silent_controller_times_out_naming_the_command() {
    let (master, path) = pty();
    let _device = controller(master, 1);
    let mut wheel = SerialWheel::open(&path).unwrap();
    wheel.set_speed_hz(1000.0).unwrap();
    match wheel.start() {
        Err(Error::Timeout { device, what, .. }) => {
            assert_eq!((device.as_str(), what.as_str()), ("wheel", "START"))
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn status_replies_are_checked() {
    assert!(parse_status("STATUS 1 1000 999.9 1 42").unwrap().locked);
    for bad in [
        "STATUS 1 1000",
        "STATUS 2 1000 1000 1 4",
        "STATUS 1 nan 1 1 4",
        "OK",
    ] {
        let msg = parse_status(bad).unwrap_err().to_string();
        assert!(msg.contains(bad), "{msg}");
    }
}
