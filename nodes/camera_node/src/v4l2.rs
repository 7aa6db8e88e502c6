//! A V4L2 webcam: asks for MJPEG at the configured size and rate and passes its frames
//! through as they are; a camera without MJPEG is asked for YUYV, whose frames are
//! encoded to JPEG here. Memory-mapped streaming with 4 buffers; a read waits 2 s at
//! most, so an unplugged camera is noticed. Stamps: the system clock (ROS time) when
//! the frame is dequeued.
//!
//! This machine has no camera: this module is exercised only with a real webcam
//! (docs/nodes.md, `camera_node`). Its pure parts (YUYV conversion, encoding, sequence
//! gaps) are tested here and in [`crate::jpeg`].

use crate::config::Config;
use crate::jpeg;
use crate::source::{Camera, CameraError, Frame, Opened};
use eezybot_msgs::Time;
use std::time::Duration;
use v4l::buffer::Type;
use v4l::io::mmap::Stream as MmapStream;
use v4l::io::traits::CaptureStream;
use v4l::video::capture::Parameters;
use v4l::video::Capture;
use v4l::{Device, FourCC};

/// How the frames become JPEG.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// The camera's JPEG, passed through.
    Mjpeg,
    /// YUYV 4:2:2, encoded here.
    Yuyv,
}

struct Streaming {
    // The stream holds the device's handle (an Arc); the device is kept for clarity.
    _device: Device,
    stream: MmapStream<'static>,
    kind: Kind,
    width: u32,
    height: u32,
    /// bytes a row (V4L2's bytesperline)
    stride: u32,
    last_sequence: Option<u32>,
}

/// A V4L2 capture device.
pub struct V4l2Camera {
    config: Config,
    open: Option<Streaming>,
}

impl V4l2Camera {
    /// The camera of `config.device`, not opened yet.
    pub fn new(config: &Config) -> Self {
        V4l2Camera {
            config: config.clone(),
            open: None,
        }
    }

    fn open_error(&self, reason: impl std::fmt::Display) -> CameraError {
        CameraError::Open {
            device: self.config.device.clone(),
            reason: reason.to_string(),
        }
    }
}

/// Frames lost between two V4L2 sequence numbers.
pub fn sequence_gap(last: Option<u32>, now: u32) -> u64 {
    match last {
        Some(l) => u64::from(now.wrapping_sub(l).saturating_sub(1)),
        None => 0,
    }
}

impl Camera for V4l2Camera {
    fn open(&mut self) -> Result<Opened, CameraError> {
        self.open = None;
        let c = &self.config;
        let device = Device::with_path(&c.device).map_err(|e| self.open_error(e))?;
        let mut want = device
            .format()
            .map_err(|e| self.open_error(format!("get format: {e}")))?;
        want.width = c.width;
        want.height = c.height;
        let mut kind = None;
        let mut got = want;
        for (fourcc, k) in [
            (FourCC::new(b"MJPG"), Kind::Mjpeg),
            (FourCC::new(b"YUYV"), Kind::Yuyv),
        ] {
            want.fourcc = fourcc;
            got = device
                .set_format(&want)
                .map_err(|e| self.open_error(format!("set format {fourcc}: {e}")))?;
            if got.fourcc == fourcc {
                kind = Some(k);
                break;
            }
        }
        let Some(kind) = kind else {
            return Err(CameraError::Format {
                device: c.device.clone(),
                offered: got.fourcc.to_string(),
            });
        };
        // A camera that cannot set its rate keeps its own: reported, not fatal.
        let fps = match device.set_params(&Parameters::with_fps(c.fps)) {
            Ok(p) if p.interval.numerator > 0 => {
                f64::from(p.interval.denominator) / f64::from(p.interval.numerator)
            }
            Ok(_) => f64::from(c.fps),
            Err(e) => {
                log::warn!("{}: cannot set {} fps: {e}", c.device, c.fps);
                0.0
            }
        };
        let mut stream = MmapStream::with_buffers(&device, Type::VideoCapture, 4)
            .map_err(|e| self.open_error(format!("buffers: {e}")))?;
        stream.set_timeout(Duration::from_secs(2));
        let format = match kind {
            Kind::Mjpeg => "MJPG (passed through)",
            Kind::Yuyv => "YUYV (encoded to JPEG)",
        };
        self.open = Some(Streaming {
            _device: device,
            stream,
            kind,
            width: got.width,
            height: got.height,
            stride: got.stride,
            last_sequence: None,
        });
        Ok(Opened {
            format: format.into(),
            width: got.width,
            height: got.height,
            fps,
        })
    }

    fn read(&mut self) -> Result<Frame, CameraError> {
        let device = self.config.device.clone();
        let quality = self.config.jpeg_quality;
        let read_error = |reason: String| CameraError::Read {
            device: device.clone(),
            reason,
        };
        let s = self
            .open
            .as_mut()
            .ok_or_else(|| read_error("not open".into()))?;
        let (buf, meta) = s.stream.next().map_err(|e| read_error(e.to_string()))?;
        let stamp = Time::now();
        let used = (meta.bytesused as usize).min(buf.len());
        let data = &buf[..used];
        let dropped_before = sequence_gap(s.last_sequence, meta.sequence);
        s.last_sequence = Some(meta.sequence);
        let (w, h) = (s.width as usize, s.height as usize);
        let jpeg = match s.kind {
            Kind::Mjpeg => {
                if data.len() < 4 || data[..2] != [0xff, 0xd8] {
                    return Err(read_error(format!(
                        "a frame of {} bytes that is not JPEG",
                        data.len()
                    )));
                }
                data.to_vec()
            }
            Kind::Yuyv => jpeg::yuyv_to_rgb(data, w, h, s.stride as usize)
                .and_then(|rgb| jpeg::encode_rgb(&rgb, w, h, quality))
                .map_err(|source| CameraError::Encode {
                    device: device.clone(),
                    source,
                })?,
        };
        Ok(Frame {
            stamp,
            jpeg,
            width: s.width,
            height: s.height,
            dropped_before,
        })
    }

    fn close(&mut self) {
        self.open = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequence_gaps_count_the_frames_missing_between_two_numbers() {
        assert_eq!(sequence_gap(None, 7), 0);
        assert_eq!(sequence_gap(Some(7), 8), 0);
        assert_eq!(sequence_gap(Some(7), 10), 2);
        assert_eq!(sequence_gap(Some(u32::MAX), 1), 1);
        assert_eq!(sequence_gap(Some(5), 5), 0);
    }

    #[test]
    fn a_missing_device_is_an_open_error_naming_it() {
        let mut cam = V4l2Camera::new(&Config {
            device: "/dev/video99-missing".into(),
            ..Config::default()
        });
        let e = cam.open().unwrap_err().to_string();
        assert!(e.contains("/dev/video99-missing"), "{e}");
        assert!(matches!(cam.read(), Err(CameraError::Read { .. })));
    }
}
