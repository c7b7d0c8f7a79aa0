//! A GenICam camera (GigE Vision or USB3 Vision) through Aravis 0.8 (`libaravis-0.8`), configured
//! by SFNC feature names. GigE streams are opened with the packet socket disabled and the socket
//! buffer sized to the payload, which loopback (`arv-fake-gv-camera-0.8 -i 127.0.0.1`) needs and
//! real links tolerate. Chunk counters are read where the camera has them (docs/controller.md).

use crate::devices::{Camera, CameraInfo, ExposureMode, Frame, TriggerMode, TriggerSource};
use crate::error::{Error, Result};
use crate::log::{Event, EventLog, Kind};
use aravis::glib;
use aravis::prelude::*;
use aravis::{BufferStatus, GvStream, GvStreamOption, GvStreamSocketBuffer};
use glib::prelude::Cast;
use std::time::Instant;

const DEVICE: &str = "camera";

/// Frame buffers handed to the stream.
const BUFFERS: usize = 16;

/// A camera opened by Aravis.
pub struct AravisCamera {
    camera: aravis::Camera,
    stream: Option<aravis::Stream>,
    name: String,
    /// `ExposureTime` (SFNC) or `ExposureTimeAbs` (older GigE cameras, the fake camera).
    exposure_feature: &'static str,
    exposure_s: f64,
    /// Reads ChunkCounterValue where the camera has counter chunks (None otherwise).
    counters: Option<aravis::ChunkParser>,
    /// The last raw frame id and the count it was unwrapped by.
    ids: (u64, u64),
    log: EventLog,
    opened: Instant,
}

fn failed(what: impl std::fmt::Display, e: glib::Error) -> Error {
    Error::device(DEVICE, format!("{what}: {e}"))
}

impl AravisCamera {
    /// Open the camera Aravis knows as `name` (its id, e.g. `Aravis-Fake-NAME`, or its IP
    /// address); the first camera found when `name` is empty.
    pub fn open(name: &str) -> Result<AravisCamera> {
        let camera = aravis::Camera::new((!name.is_empty()).then_some(name))
            .map_err(|e| failed(format!("no GenICam camera `{name}`"), e))?;
        let has = |f: &str| camera.is_feature_available(f).unwrap_or(false);
        let exposure_feature = if has("ExposureTime") {
            "ExposureTime"
        } else if has("ExposureTimeAbs") {
            "ExposureTimeAbs"
        } else {
            return Err(Error::device(
                DEVICE,
                format!("`{name}` has neither ExposureTime nor ExposureTimeAbs"),
            ));
        };
        let exposure_s = camera.float(exposure_feature).unwrap_or(0.0) * 1e-6;
        let counters = if has("ChunkCounterValue") {
            camera.create_chunk_parser()
        } else {
            None
        };
        Ok(AravisCamera {
            camera,
            stream: None,
            name: name.to_string(),
            exposure_feature,
            exposure_s,
            counters,
            ids: (0, 0),
            log: EventLog::default(),
            opened: Instant::now(),
        })
    }

    fn now_ns(&self) -> u64 {
        self.opened.elapsed().as_nanos() as u64
    }

    fn has(&self, feature: &str) -> bool {
        self.camera.is_feature_available(feature).unwrap_or(false)
    }

    /// Set an enumeration feature by its entry name, logged as `Feature=Value`.
    fn set_enum(&mut self, feature: &str, value: &str) -> Result<()> {
        let t = self.now_ns();
        self.log
            .push(t, DEVICE, Kind::Command, format!("{feature}={value}"));
        self.camera
            .set_string(feature, value)
            .map_err(|e| failed(format!("{feature}={value}"), e))
    }

    fn set_float(&mut self, feature: &str, value: f64) -> Result<()> {
        let t = self.now_ns();
        self.log
            .push(t, DEVICE, Kind::Command, format!("{feature}={value}"));
        self.camera
            .set_float(feature, value)
            .map_err(|e| failed(format!("{feature}={value}"), e))
    }

    fn int(&self, feature: &str) -> Result<usize> {
        let v = self
            .camera
            .integer(feature)
            .map_err(|e| failed(feature, e))?;
        usize::try_from(v).map_err(|_| Error::device(DEVICE, format!("{feature} = {v}")))
    }

    /// Sample bits of the current PixelFormat; only monochrome formats are accepted.
    fn pixel_bits(&self) -> Result<u32> {
        let f = self
            .camera
            .pixel_format_as_string()
            .map_err(|e| failed("PixelFormat", e))?;
        match f.as_str() {
            "Mono8" => Ok(8),
            "Mono10" => Ok(10),
            "Mono12" => Ok(12),
            "Mono14" => Ok(14),
            "Mono16" => Ok(16),
            other => Err(Error::device(
                DEVICE,
                format!("PixelFormat={other}: only unpacked Mono8..Mono16 are read"),
            )),
        }
    }

    /// Set PixelFormat (e.g. `Mono16`) and the region's Width/Height.
    pub fn set_format(&mut self, pixel_format: &str, width: usize, height: usize) -> Result<()> {
        self.set_enum("PixelFormat", pixel_format)?;
        for (feature, v) in [("Width", width), ("Height", height)] {
            let t = self.now_ns();
            self.log
                .push(t, DEVICE, Kind::Command, format!("{feature}={v}"));
            self.camera
                .set_integer(feature, v as i64)
                .map_err(|e| failed(format!("{feature}={v}"), e))?;
        }
        Ok(())
    }

    /// TriggerSoftware: one frame when the trigger source is Software.
    pub fn software_trigger(&mut self) -> Result<()> {
        let t = self.now_ns();
        self.log.push(t, DEVICE, Kind::Command, "TriggerSoftware");
        self.camera
            .execute_command("TriggerSoftware")
            .map_err(|e| failed("TriggerSoftware", e))
    }

    /// A stream with `BUFFERS` payload-sized buffers: packet socket off, automatic socket
    /// buffer (GigE only; without them no frame arrives over loopback).
    fn open_stream(&self) -> Result<aravis::Stream> {
        if self.camera.is_gv_device() {
            self.camera
                .gv_set_stream_options(GvStreamOption::PACKET_SOCKET_DISABLED);
        }
        let stream = self
            .camera
            .create_stream()
            .map_err(|e| failed(format!("stream of `{}`", self.name), e))?;
        if let Some(gv) = stream.downcast_ref::<GvStream>() {
            gv.set_socket_buffer(GvStreamSocketBuffer::Auto);
        }
        let payload = self
            .camera
            .payload()
            .map_err(|e| failed("PayloadSize", e))?;
        for _ in 0..BUFFERS {
            stream.push_buffer(aravis::Buffer::new_allocate(payload as usize));
        }
        Ok(stream)
    }

    /// The camera's clock now (TimestampLatch/TimestampLatchValue, ns); 0 where the camera
    /// cannot latch it, so no delivered frame counts as stale (disarm drops queued frames).
    fn latch_timestamp(&self) -> Result<u64> {
        if !self.has("TimestampLatch") {
            return Ok(0);
        }
        self.camera
            .execute_command("TimestampLatch")
            .map_err(|e| failed("TimestampLatch", e))?;
        let v = self
            .camera
            .integer("TimestampLatchValue")
            .map_err(|e| failed("TimestampLatchValue", e))?;
        Ok(v.max(0) as u64)
    }

    /// Whether frames carry the Line1/Line2 edge counters (ChunkCounterValue) the controller
    /// checks each exposure against; without them every frame is flagged.
    pub fn has_counters(&self) -> bool {
        self.counters.is_some()
    }

    /// A chunk counter's value (ChunkCounterSelector), 0 where the camera sends no counters.
    fn chunk_counter(&self, buffer: &aravis::Buffer, counter: &str) -> u32 {
        let Some(parser) = &self.counters else {
            return 0;
        };
        let _ = self.camera.set_string("ChunkCounterSelector", counter);
        parser
            .integer_value(buffer, "ChunkCounterValue")
            .map_or(0, |v| v.max(0) as u32)
    }
}

/// Raw samples of one buffer as u16: one byte per pixel (Mono8) or two little-endian bytes.
fn samples(bytes: &[u8], bits: u32, n: usize) -> Result<Vec<u16>> {
    let per = if bits <= 8 { 1 } else { 2 };
    if bytes.len() < n * per {
        return Err(Error::device(
            DEVICE,
            format!(
                "a buffer of {} bytes for {n} pixels of {bits} bits",
                bytes.len()
            ),
        ));
    }
    Ok(if per == 1 {
        bytes[..n].iter().map(|&b| b as u16).collect()
    } else {
        bytes[..2 * n]
            .chunks_exact(2)
            .map(|c| u16::from_le_bytes([c[0], c[1]]))
            .collect()
    })
}

/// GigE Vision 1.x block ids are 16 bits and skip 0 (65535 is followed by 1): a smaller raw id
/// after one in the top quarter of that range is a wrap, so the frame id keeps counting.
/// `(last raw id, offset)` in and out.
fn unwrap_id((last, offset): (u64, u64), raw: u64) -> (u64, u64) {
    if raw < last && last > 0xC000 && last <= 0xFFFF {
        (raw, offset + 0xFFFF)
    } else {
        (raw, offset)
    }
}

impl Camera for AravisCamera {
    fn inquire(&mut self) -> Result<CameraInfo> {
        let (lo, hi) = self
            .camera
            .float_bounds(self.exposure_feature)
            .map_err(|e| failed(self.exposure_feature, e))?;
        let max_frame_rate_hz = if self.has("AcquisitionFrameRate") {
            self.camera
                .float_bounds("AcquisitionFrameRate")
                .map_err(|e| failed("AcquisitionFrameRate", e))?
                .1
        } else {
            f64::INFINITY
        };
        let readout_s = if self.has("SensorReadoutTime") {
            self.camera
                .float("SensorReadoutTime")
                .map_err(|e| failed("SensorReadoutTime", e))?
                * 1e-6
        } else {
            0.0
        };
        Ok(CameraInfo {
            width: self.int("Width")?,
            height: self.int("Height")?,
            bits: self.pixel_bits()?,
            min_exposure_s: lo * 1e-6,
            max_exposure_s: hi * 1e-6,
            max_frame_rate_hz,
            readout_s,
        })
    }

    fn set_trigger_mode(&mut self, mode: TriggerMode) -> Result<()> {
        self.set_enum("TriggerSelector", "FrameStart")?;
        self.set_enum(
            "TriggerMode",
            if mode == TriggerMode::On { "On" } else { "Off" },
        )
    }

    fn set_trigger_source(&mut self, source: TriggerSource) -> Result<()> {
        let name = match source {
            TriggerSource::Line1 => "Line1",
            TriggerSource::Line2 => "Line2",
            TriggerSource::Software => "Software",
        };
        self.set_enum("TriggerSource", name)
    }

    fn set_trigger_divider(&mut self, n: u32) -> Result<()> {
        if n == 1 && !self.has("TriggerDivider") {
            return Ok(());
        }
        let t = self.now_ns();
        self.log
            .push(t, DEVICE, Kind::Command, format!("TriggerDivider={n}"));
        self.camera
            .set_integer("TriggerDivider", n as i64)
            .map_err(|e| failed(format!("TriggerDivider={n}"), e))
    }

    fn set_exposure_mode(&mut self, mode: ExposureMode) -> Result<()> {
        let name = match mode {
            ExposureMode::Timed => "Timed",
            ExposureMode::TriggerWidth => "TriggerWidth",
        };
        // A camera without ExposureMode exposes for ExposureTime: Timed is what it does.
        if mode == ExposureMode::Timed && !self.has("ExposureMode") {
            return Ok(());
        }
        self.set_enum("ExposureMode", name)
    }

    fn set_exposure_time_s(&mut self, s: f64) -> Result<()> {
        self.set_float(self.exposure_feature, s * 1e6)?;
        self.exposure_s = s;
        Ok(())
    }

    fn set_acquisition_frame_rate_hz(&mut self, hz: f64) -> Result<()> {
        if self.has("AcquisitionFrameRateEnable") {
            self.camera
                .set_boolean("AcquisitionFrameRateEnable", true)
                .map_err(|e| failed("AcquisitionFrameRateEnable=true", e))?;
        }
        self.set_float("AcquisitionFrameRate", hz)
    }

    fn arm(&mut self) -> Result<u64> {
        if self.stream.is_none() {
            self.stream = Some(self.open_stream()?);
        }
        self.set_enum("AcquisitionMode", "Continuous")?;
        let latched = self.latch_timestamp()?;
        let t = self.now_ns();
        self.log.push(t, DEVICE, Kind::Command, "AcquisitionStart");
        self.camera
            .start_acquisition()
            .map_err(|e| failed("AcquisitionStart", e))?;
        Ok(latched)
    }

    fn disarm(&mut self) -> Result<()> {
        let t = self.now_ns();
        self.log.push(t, DEVICE, Kind::Command, "AcquisitionStop");
        self.camera
            .stop_acquisition()
            .map_err(|e| failed("AcquisitionStop", e))?;
        if let Some(stream) = &self.stream {
            while let Some(b) = stream.try_pop_buffer() {
                stream.push_buffer(b);
            }
        }
        Ok(())
    }

    fn next_frame(&mut self, timeout_s: f64) -> Result<Frame> {
        let stream = self
            .stream
            .clone()
            .ok_or_else(|| Error::device(DEVICE, "next frame asked before AcquisitionStart"))?;
        let Some(buffer) = stream.timeout_pop_buffer((timeout_s * 1e6) as u64) else {
            return Err(Error::Timeout {
                device: DEVICE.into(),
                what: "the next frame".into(),
                after_s: timeout_s,
            });
        };
        let frame = self.frame_of(&buffer);
        stream.push_buffer(buffer);
        frame
    }

    fn events(&self) -> Vec<Event> {
        self.log.entries().to_vec()
    }
}

impl AravisCamera {
    /// The frame a delivered buffer holds; an incomplete buffer is an error naming its status.
    fn frame_of(&mut self, buffer: &aravis::Buffer) -> Result<Frame> {
        let status = buffer.status();
        if status != BufferStatus::Success {
            return Err(Error::device(
                DEVICE,
                format!("frame {} arrived {status:?}", buffer.frame_id()),
            ));
        }
        let (width, height) = (
            buffer.image_width() as usize,
            buffer.image_height() as usize,
        );
        let data = samples(&buffer.image_data(), self.pixel_bits()?, width * height)?;
        let t = self.now_ns();
        self.log.push(
            t,
            DEVICE,
            Kind::Edge,
            format!("frame {} delivered", buffer.frame_id()),
        );
        self.ids = unwrap_id(self.ids, buffer.frame_id());
        Ok(Frame {
            frame_id: self.ids.0 + self.ids.1,
            timestamp_ns: buffer.timestamp(),
            exposure_s: self.exposure_s,
            line1_edges: self.chunk_counter(buffer, "Counter0"),
            line2_edges: self.chunk_counter(buffer, "Counter1"),
            width,
            height,
            data,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sixteen_bit_block_ids_keep_counting_across_the_wrap() {
        let mut state = (0, 0);
        let ids: Vec<u64> = [65534, 65535, 1, 2]
            .into_iter()
            .map(|raw| {
                state = unwrap_id(state, raw);
                state.0 + state.1
            })
            .collect();
        assert_eq!(ids, [65534, 65535, 65536, 65537]);
    }

    #[test]
    fn mono8_and_mono16_samples() {
        assert_eq!(samples(&[1, 2, 3], 8, 3).unwrap(), [1, 2, 3]);
        assert_eq!(samples(&[1, 2, 3, 4], 12, 2).unwrap(), [0x0201, 0x0403]);
        assert!(samples(&[1, 2, 3], 16, 2).is_err());
    }
}
