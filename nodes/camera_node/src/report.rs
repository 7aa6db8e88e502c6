//! The node's core: [`Event`]s of the capture in, messages and the diagnostics entry
//! out, on a given clock; no I/O.

use crate::config::Config;
use crate::source::{Event, Frame, Opened};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::{CameraInfo, CompressedImage};
use eezybot_msgs::std_msgs::Header;
use ros_plumbing::diagnostics::status;
use std::time::Instant;

/// Where the camera is, as the diagnostics entry says it.
#[derive(Clone, Debug, PartialEq)]
enum State {
    Starting,
    Streaming(Opened),
    Failed(String),
}

/// The node's state between events.
#[derive(Debug)]
pub struct CameraCore {
    config: Config,
    diag_name: String,
    state: State,
    published: u64,
    dropped: u64,
    failures: u64,
    last_error: Option<String>,
    window_start: Instant,
    window_frames: u64,
}

/// What one frame becomes: the image and its camera info, with the same header.
#[derive(Clone, Debug, PartialEq)]
pub struct Publish {
    /// for `camera/image_raw/compressed`
    pub image: CompressedImage,
    /// for `camera/camera_info`
    pub info: CameraInfo,
}

impl CameraCore {
    /// Nothing captured yet at `now`; the diagnostics entry is named `diag_name`.
    pub fn new(config: Config, diag_name: String, now: Instant) -> Self {
        CameraCore {
            config,
            diag_name,
            state: State::Starting,
            published: 0,
            dropped: 0,
            failures: 0,
            last_error: None,
            window_start: now,
            window_frames: 0,
        }
    }

    /// An event of the capture: a frame becomes a [`Publish`]; an open or a failure
    /// changes the state (and is logged, a failure once until the camera opens again or
    /// the reason changes).
    pub fn on_event(&mut self, event: Event) -> Option<Publish> {
        match event {
            Event::Frame(f) => Some(self.on_frame(f)),
            Event::Opened(o) => {
                log::info!(
                    "{}: {} {}x{} at {} fps",
                    self.config.device,
                    o.format,
                    o.width,
                    o.height,
                    o.fps
                );
                self.state = State::Streaming(o);
                None
            }
            Event::Failed { reason, retry_in } => {
                self.failures += 1;
                if self.state != State::Failed(reason.clone()) {
                    log::warn!("{reason}; trying again every {} s", retry_in.as_secs_f64());
                }
                self.last_error = Some(reason.clone());
                self.state = State::Failed(reason);
                None
            }
        }
    }

    fn on_frame(&mut self, f: Frame) -> Publish {
        self.published += 1;
        self.window_frames += 1;
        self.dropped += f.dropped_before;
        let header = Header {
            stamp: f.stamp,
            frame_id: self.config.frame_id.clone(),
        };
        Publish {
            info: CameraInfo {
                header: header.clone(),
                height: f.height,
                width: f.width,
                ..CameraInfo::default()
            },
            image: CompressedImage {
                header,
                format: "jpeg".into(),
                data: f.jpeg,
            },
        }
    }

    /// The diagnostics entry at `now`; its `fps` is the frames published since the
    /// previous report, a second.
    pub fn report(&mut self, now: Instant) -> DiagnosticStatus {
        let secs = now.duration_since(self.window_start).as_secs_f64();
        let fps = if secs > 0.0 {
            self.window_frames as f64 / secs
        } else {
            0.0
        };
        self.window_start = now;
        self.window_frames = 0;
        let c = &self.config;
        let (level, message, format, size) = match &self.state {
            State::Starting => (
                DiagnosticStatus::WARN,
                format!("opening {}", c.device),
                String::new(),
                format!("{}x{}", c.width, c.height),
            ),
            State::Streaming(o) => (
                DiagnosticStatus::OK,
                format!("streaming {}x{} {}", o.width, o.height, o.format),
                o.format.clone(),
                format!("{}x{}", o.width, o.height),
            ),
            State::Failed(reason) => (
                DiagnosticStatus::ERROR,
                format!("{reason}; trying again every second"),
                String::new(),
                format!("{}x{}", c.width, c.height),
            ),
        };
        status(
            level,
            &self.diag_name,
            &c.device,
            &message,
            &[
                ("device", c.device.clone()),
                ("format", format),
                ("size", size),
                ("fps_requested", c.fps.to_string()),
                ("fps_actual", format!("{fps:.1}")),
                ("frames_published", self.published.to_string()),
                ("frames_dropped", self.dropped.to_string()),
                ("failures", self.failures.to_string()),
                ("last_error", self.last_error.clone().unwrap_or_default()),
                ("frame_id", c.frame_id.clone()),
            ],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use eezybot_msgs::Time;
    use std::time::Duration;

    fn value<'a>(s: &'a DiagnosticStatus, key: &str) -> &'a str {
        &s.values.iter().find(|kv| kv.key == key).unwrap().value
    }

    #[test]
    fn frames_become_images_and_infos_with_one_header_and_the_report_counts_them() {
        let t0 = Instant::now();
        let config = Config {
            frame_id: "wrist".into(),
            ..Config::default()
        };
        let mut core = CameraCore::new(config, "wrist: camera".into(), t0);
        assert_eq!(core.report(t0).level, DiagnosticStatus::WARN);
        let failed = Event::Failed {
            reason: "cannot open /dev/video0: No such file or directory".into(),
            retry_in: Duration::from_secs(1),
        };
        assert_eq!(core.on_event(failed.clone()), None);
        assert_eq!(core.on_event(failed), None);
        let s = core.report(t0);
        assert_eq!(s.level, DiagnosticStatus::ERROR);
        assert!(
            s.message.contains("/dev/video0: No such file"),
            "{}",
            s.message
        );
        assert_eq!(value(&s, "failures"), "2");
        core.on_event(Event::Opened(Opened {
            format: "MJPG (passed through)".into(),
            width: 320,
            height: 240,
            fps: 30.0,
        }));
        for i in 0..10 {
            let p = core
                .on_event(Event::Frame(Frame {
                    stamp: Time::new(100, i),
                    jpeg: vec![0xff, 0xd8, i as u8],
                    width: 320,
                    height: 240,
                    dropped_before: u64::from(i == 3) * 2,
                }))
                .unwrap();
            assert_eq!(p.image.header, p.info.header);
            assert_eq!(p.image.header.stamp, Time::new(100, i));
            assert_eq!(p.image.header.frame_id, "wrist");
            assert_eq!(p.image.format, "jpeg");
            assert_eq!((p.info.width, p.info.height), (320, 240));
        }
        let s = core.report(t0 + Duration::from_secs(2));
        assert_eq!(s.level, DiagnosticStatus::OK);
        assert_eq!(s.name, "wrist: camera");
        assert_eq!(value(&s, "frames_published"), "10");
        assert_eq!(value(&s, "frames_dropped"), "2");
        assert_eq!(value(&s, "fps_actual"), "5.0");
        assert_eq!(value(&s, "size"), "320x240");
        assert_eq!(value(&s, "format"), "MJPG (passed through)");
        assert!(value(&s, "last_error").contains("/dev/video0"));
    }
}
