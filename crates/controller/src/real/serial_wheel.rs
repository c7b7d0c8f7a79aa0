//! A colour-wheel motor controller on a serial line, with a small line protocol (ASCII, one
//! command per line, `\n`-terminated, one reply line each, 115200 8N1):
//!
//! | command        | reply                                                         |
//! | -------------- | ------------------------------------------------------------- |
//! | `SPEED <rev/s>`| `OK` or `ERR <reason>`                                        |
//! | `START`        | `OK` or `ERR <reason>`                                        |
//! | `STOP`         | `OK`                                                          |
//! | `STATUS?`      | `STATUS <spinning 0/1> <target> <measured> <locked 0/1> <index pulses>` |
//!
//! A reply that does not come within `REPLY_TIMEOUT_S` is a timeout error naming the command.
//! The index pulse itself is a hardware line to the DMD's trigger-in, not on this link.

use crate::devices::{ColorWheel, WheelStatus};
use crate::error::{Error, Result};
use crate::log::{Event, EventLog, Kind};
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::time::{Duration, Instant};

const DEVICE: &str = "wheel";

/// How long a reply may take.
pub const REPLY_TIMEOUT_S: f64 = 0.5;

/// How often `wait_for_lock` asks for the status.
const POLL_S: f64 = 0.05;

/// The wheel's controller on a serial port (or a pseudo-terminal standing in for one).
pub struct SerialWheel {
    port: File,
    pending: Vec<u8>,
    log: EventLog,
    t0: Instant,
}

impl SerialWheel {
    /// Open `path` (e.g. /dev/ttyUSB0) raw at 115200 baud.
    pub fn open(path: &Path) -> Result<SerialWheel> {
        let port = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NOCTTY)
            .open(path)
            .map_err(|e| Error::device(DEVICE, format!("{}: {e}", path.display())))?;
        raw_115200(&port).map_err(|e| Error::device(DEVICE, format!("{}: {e}", path.display())))?;
        Ok(SerialWheel {
            port,
            pending: Vec::new(),
            log: EventLog::default(),
            t0: Instant::now(),
        })
    }

    fn now_ns(&self) -> u64 {
        self.t0.elapsed().as_nanos() as u64
    }

    /// Send one line and read its reply; `ERR …` becomes a device error.
    fn ask(&mut self, kind: Kind, line: &str) -> Result<String> {
        self.log.push(self.now_ns(), DEVICE, kind, line);
        self.port
            .write_all(format!("{line}\n").as_bytes())
            .map_err(|e| Error::device(DEVICE, format!("{line}: {e}")))?;
        let reply = self.read_line(line)?;
        match reply.strip_prefix("ERR") {
            Some(why) => Err(Error::device(DEVICE, format!("{line}: {}", why.trim()))),
            None => Ok(reply),
        }
    }

    /// One reply line, waiting at most `REPLY_TIMEOUT_S` (poll, then read what is there).
    fn read_line(&mut self, what: &str) -> Result<String> {
        let deadline = Instant::now() + Duration::from_secs_f64(REPLY_TIMEOUT_S);
        loop {
            if let Some(end) = self.pending.iter().position(|&b| b == b'\n') {
                let line: Vec<u8> = self.pending.drain(..=end).collect();
                return Ok(String::from_utf8_lossy(&line).trim().to_string());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() || !readable(&self.port, left) {
                return Err(Error::Timeout {
                    device: DEVICE.into(),
                    what: what.into(),
                    after_s: REPLY_TIMEOUT_S,
                });
            }
            let mut buf = [0u8; 256];
            match self.port.read(&mut buf) {
                Ok(0) => return Err(Error::device(DEVICE, format!("{what}: the line closed"))),
                Ok(n) => self.pending.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Error::device(DEVICE, format!("{what}: {e}"))),
            }
        }
    }

    fn expect_ok(&mut self, line: &str) -> Result<()> {
        match self.ask(Kind::Command, line)?.as_str() {
            "OK" => Ok(()),
            other => Err(Error::device(
                DEVICE,
                format!("{line}: unexpected reply `{other}`"),
            )),
        }
    }
}

/// Parse `STATUS <spinning> <target> <measured> <locked> <pulses>`.
pub fn parse_status(reply: &str) -> Result<WheelStatus> {
    let bad = || Error::device(DEVICE, format!("STATUS?: unreadable reply `{reply}`"));
    let f: Vec<&str> = reply.split_whitespace().collect();
    if f.len() != 6 || f[0] != "STATUS" {
        return Err(bad());
    }
    let flag = |s: &str| match s {
        "0" => Ok(false),
        "1" => Ok(true),
        _ => Err(bad()),
    };
    let num = |s: &str| {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(bad)
    };
    Ok(WheelStatus {
        spinning: flag(f[1])?,
        target_hz: num(f[2])?,
        measured_hz: num(f[3])?,
        locked: flag(f[4])?,
        index_pulses: f[5].parse().map_err(|_| bad())?,
    })
}

impl ColorWheel for SerialWheel {
    fn set_speed_hz(&mut self, rev_per_s: f64) -> Result<()> {
        if !(rev_per_s.is_finite() && rev_per_s > 0.0) {
            return Err(Error::device(
                DEVICE,
                format!("SPEED {rev_per_s}: must be a finite speed > 0"),
            ));
        }
        self.expect_ok(&format!("SPEED {rev_per_s}"))
    }

    fn start(&mut self) -> Result<()> {
        self.expect_ok("START")
    }

    fn stop(&mut self) -> Result<()> {
        self.expect_ok("STOP")
    }

    fn status(&mut self) -> Result<WheelStatus> {
        let reply = self.ask(Kind::Inquiry, "STATUS?")?;
        parse_status(&reply)
    }

    fn wait_for_lock(&mut self, timeout_s: f64) -> Result<WheelStatus> {
        let deadline = Instant::now() + Duration::from_secs_f64(timeout_s.max(0.0));
        loop {
            let s = self.status()?;
            if s.locked {
                return Ok(s);
            }
            if Instant::now() >= deadline {
                return Err(Error::Timeout {
                    device: DEVICE.into(),
                    what: format!("phase lock at {} rev/s", s.target_hz),
                    after_s: timeout_s,
                });
            }
            std::thread::sleep(Duration::from_secs_f64(POLL_S));
        }
    }

    fn events(&self) -> Vec<Event> {
        self.log.entries().to_vec()
    }
}

/// Raw mode, 115200 baud, 8N1, no flow control.
fn raw_115200(port: &File) -> std::io::Result<()> {
    let fd = port.as_raw_fd();
    // SAFETY: termios is plain data filled by tcgetattr on a descriptor we own.
    unsafe {
        let mut t: libc::termios = std::mem::zeroed();
        if libc::tcgetattr(fd, &mut t) != 0 {
            return Err(std::io::Error::last_os_error());
        }
        libc::cfmakeraw(&mut t);
        libc::cfsetispeed(&mut t, libc::B115200);
        libc::cfsetospeed(&mut t, libc::B115200);
        t.c_cflag |= libc::CLOCAL | libc::CREAD;
        if libc::tcsetattr(fd, libc::TCSANOW, &t) != 0 {
            return Err(std::io::Error::last_os_error());
        }
    }
    Ok(())
}

/// True when `port` has bytes to read within `wait`.
fn readable(port: &File, wait: Duration) -> bool {
    let mut p = libc::pollfd {
        fd: port.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let ms = wait.as_millis().clamp(1, i32::MAX as u128) as i32;
    // SAFETY: one pollfd for a descriptor we own.
    unsafe { libc::poll(&mut p, 1, ms) > 0 }
}
