//! Where frames come from: a [`Camera`] (the V4L2 device of [`crate::v4l2`] or the
//! [`TestPattern`]), and [`capture`], the loop that opens it, reads it and retries after
//! a failure ([`crate::retry::Link`]), handing [`Event`]s to the node. It runs on a
//! thread of its own: V4L2 reads block.

use crate::config::Config;
use crate::grid::FrameGrid;
use crate::jpeg::{self, EncodeError};
use crate::retry::Link;
use crate::{code, pattern};
use eezybot_msgs::Time;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// A frame, JPEG-encoded.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// When it was taken, on the publishing clock (ROS time).
    pub stamp: Time,
    /// A whole JPEG file.
    pub jpeg: Vec<u8>,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Frames lost since the previous one (passed over by a late test source, missing
    /// from the camera's sequence numbers, or not handed to the node in time).
    pub dropped_before: u64,
}

/// What an opened camera delivers.
#[derive(Clone, Debug, PartialEq)]
pub struct Opened {
    /// How the frames are made, e.g. `MJPG (passed through)`, `YUYV (encoded to JPEG)`,
    /// `test pattern`.
    pub format: String,
    /// Width, px (the camera's, which may differ from the one asked for).
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Frames a second the camera said it will deliver.
    pub fps: f64,
}

/// Why a camera could not be opened or read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CameraError {
    /// Opening or configuring the device failed.
    #[error("cannot open {device}: {reason}")]
    Open {
        /// the device path
        device: String,
        /// what failed
        reason: String,
    },
    /// The camera offers neither MJPEG nor YUYV at the size asked for.
    #[error("{device} offers neither MJPG nor YUYV (it offered {offered})")]
    Format {
        /// the device path
        device: String,
        /// the FourCC it answered with
        offered: String,
    },
    /// Reading a frame failed (e.g. the camera was unplugged).
    #[error("reading {device} failed: {reason}")]
    Read {
        /// the device path
        device: String,
        /// what failed
        reason: String,
    },
    /// A frame could not be encoded.
    #[error("{device}: {source}")]
    Encode {
        /// the device path
        device: String,
        /// the encoder's error
        source: EncodeError,
    },
    /// The test pattern could not draw its stamp code.
    #[error("test pattern: {0}")]
    Code(#[from] code::CodeError),
}

/// A source of frames.
pub trait Camera {
    /// Open it (again after a failure).
    fn open(&mut self) -> Result<Opened, CameraError>;
    /// The next frame; blocks until it comes.
    fn read(&mut self) -> Result<Frame, CameraError>;
    /// Close it after a failure (a later [`Camera::open`] starts afresh).
    fn close(&mut self);
}

/// What [`capture`] reports.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// The camera opened.
    Opened(Opened),
    /// A frame.
    Frame(Frame),
    /// Opening or reading failed; the next attempt is in `retry_in`.
    Failed {
        /// why, naming the device
        reason: String,
        /// when the next attempt is
        retry_in: Duration,
    },
}

/// Open `camera`, read it and hand each frame to `emit` until `stop` is set; after a
/// failure ([`Event::Failed`]) close it and open it again `retry` later. `emit` returns
/// whether the event was taken: a frame not taken is counted in the next frame's
/// [`Frame::dropped_before`].
pub fn capture(
    camera: &mut dyn Camera,
    retry: Duration,
    stop: &AtomicBool,
    mut emit: impl FnMut(Event) -> bool,
) {
    let mut link = Link::with_retry(Instant::now(), retry);
    let mut undelivered = 0u64;
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if let Some(at) = link.retry_at() {
            if now < at {
                std::thread::sleep((at - now).min(Duration::from_millis(100)));
                continue;
            }
            match camera.open() {
                Ok(o) => {
                    link.opened();
                    emit(Event::Opened(o));
                }
                Err(e) => {
                    link.failed(e.to_string(), Instant::now());
                    emit(Event::Failed {
                        reason: e.to_string(),
                        retry_in: retry,
                    });
                }
            }
            continue;
        }
        match camera.read() {
            Ok(mut f) => {
                f.dropped_before += undelivered;
                let dropped = f.dropped_before;
                if emit(Event::Frame(f)) {
                    undelivered = 0;
                } else {
                    undelivered = dropped + 1;
                }
            }
            Err(e) => {
                camera.close();
                link.failed(e.to_string(), Instant::now());
                emit(Event::Failed {
                    reason: e.to_string(),
                    retry_in: retry,
                });
            }
        }
    }
    camera.close();
}

/// The built-in test source (`device:=test`): [`pattern::frame_rgb`] at the configured
/// size, one frame per slot of a [`FrameGrid`] of 1/fps started when it opens, each
/// stamped with its slot's time on the system clock (ROS time) and drawn with that stamp.
pub struct TestPattern {
    width: usize,
    height: usize,
    fps: u32,
    quality: u8,
    grid: Option<FrameGrid>,
}

/// The system clock, ns since the epoch (ROS time).
fn now_ns() -> i64 {
    Time::now().to_nanos()
}

impl TestPattern {
    /// A test source of `config`'s size, rate and JPEG quality.
    pub fn new(config: &Config) -> Self {
        TestPattern {
            width: config.width as usize,
            height: config.height as usize,
            fps: config.fps,
            quality: config.jpeg_quality,
            grid: None,
        }
    }
}

impl Camera for TestPattern {
    fn open(&mut self) -> Result<Opened, CameraError> {
        code::Layout::of(self.width, self.height).ok_or(code::CodeError::TooSmall {
            width: self.width,
            height: self.height,
        })?;
        self.grid = Some(FrameGrid::new(now_ns(), self.fps));
        Ok(Opened {
            format: "test pattern (encoded to JPEG)".into(),
            width: self.width as u32,
            height: self.height as u32,
            fps: f64::from(self.fps),
        })
    }

    fn read(&mut self) -> Result<Frame, CameraError> {
        let grid = self
            .grid
            .get_or_insert_with(|| FrameGrid::new(now_ns(), self.fps));
        let slot = grid.next(now_ns());
        let wait = slot.at_ns - now_ns();
        if wait > 0 {
            std::thread::sleep(Duration::from_nanos(wait as u64));
        }
        let stamp = Time::from_nanos(slot.at_ns);
        let rgb = pattern::frame_rgb(self.width, self.height, slot.index, stamp)?;
        let jpeg = jpeg::encode_rgb(&rgb, self.width, self.height, self.quality).map_err(|e| {
            CameraError::Encode {
                device: crate::config::TEST_DEVICE.into(),
                source: e,
            }
        })?;
        Ok(Frame {
            stamp,
            jpeg,
            width: self.width as u32,
            height: self.height as u32,
            dropped_before: slot.skipped,
        })
    }

    fn close(&mut self) {
        self.grid = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;

    /// A camera that plays a script: each open or read takes the next entry.
    struct Scripted {
        script: RefCell<Vec<Result<(), &'static str>>>,
        closes: u32,
    }

    impl Scripted {
        fn step(&mut self, what: &str) -> Result<(), CameraError> {
            let next = self.script.borrow_mut().remove(0);
            next.map_err(|r| CameraError::Read {
                device: what.into(),
                reason: r.into(),
            })
        }
    }

    impl Camera for Scripted {
        fn open(&mut self) -> Result<Opened, CameraError> {
            self.step("open")?;
            Ok(Opened {
                format: "scripted".into(),
                width: 2,
                height: 2,
                fps: 1.0,
            })
        }
        fn read(&mut self) -> Result<Frame, CameraError> {
            self.step("read")?;
            Ok(Frame {
                stamp: Time::ZERO,
                jpeg: vec![],
                width: 2,
                height: 2,
                dropped_before: 0,
            })
        }
        fn close(&mut self) {
            self.closes += 1;
        }
    }

    #[test]
    fn a_failing_camera_is_closed_retried_and_streams_again_without_stopping() {
        let mut cam = Scripted {
            // open fails, open, 2 frames, unplugged, open, 3 frames
            script: RefCell::new(vec![
                Err("gone"),
                Ok(()),
                Ok(()),
                Ok(()),
                Err("unplugged"),
                Ok(()),
                Ok(()),
                Ok(()),
                Ok(()),
            ]),
            closes: 0,
        };
        let stop = AtomicBool::new(false);
        let mut events = Vec::new();
        let t0 = Instant::now();
        let mut taken = 0;
        capture(&mut cam, Duration::from_millis(20), &stop, |e| {
            let frame = matches!(e, Event::Frame(_));
            events.push(e);
            if frame {
                taken += 1;
                // the 4th frame is not taken (the node's queue full): counted as dropped
                if taken == 4 {
                    return false;
                }
                if taken == 5 {
                    stop.store(true, Ordering::Relaxed);
                }
            }
            true
        });
        let kinds: Vec<String> = events
            .iter()
            .map(|e| match e {
                Event::Opened(_) => "opened".to_string(),
                Event::Frame(f) => format!("frame+{}", f.dropped_before),
                Event::Failed { reason, .. } => reason.clone(),
            })
            .collect();
        assert_eq!(
            kinds,
            [
                "reading open failed: gone",
                "opened",
                "frame+0",
                "frame+0",
                "reading read failed: unplugged",
                "opened",
                "frame+0",
                "frame+0",
                "frame+1",
            ]
        );
        assert!(t0.elapsed() >= Duration::from_millis(40), "two retries");
        assert_eq!(cam.closes, 2, "after the unplug and at the end");
    }

    #[test]
    fn the_test_pattern_stamps_frames_on_its_grid_with_the_stamp_drawn_in() {
        let config = Config {
            width: 160,
            height: 128,
            fps: 100,
            ..Config::default()
        };
        let mut cam = TestPattern::new(&config);
        let opened = cam.open().unwrap();
        assert_eq!((opened.width, opened.height), (160, 128));
        let frames: Vec<Frame> = (0..3).map(|_| cam.read().unwrap()).collect();
        for f in &frames {
            let mut d = jpeg_decoder::Decoder::new(&f.jpeg[..]);
            let rgb = d.decode().unwrap();
            assert_eq!(code::read(&rgb, 160, 128), Ok(f.stamp));
        }
        let ns: Vec<i64> = frames.iter().map(|f| f.stamp.to_nanos()).collect();
        for w in ns.windows(2) {
            let periods = (w[1] - w[0]) as f64 / 10_000_000.0;
            assert!(
                periods >= 1.0 && (periods - periods.round()).abs() < 1e-6,
                "{ns:?}"
            );
        }
        let mut tiny = TestPattern::new(&Config {
            width: 100,
            ..Config::default()
        });
        assert!(matches!(tiny.open(), Err(CameraError::Code(_))));
    }
}
