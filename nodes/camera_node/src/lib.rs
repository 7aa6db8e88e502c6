#![doc = include_str!("../README.md")]
#![cfg_attr(test, allow(clippy::unwrap_used, clippy::expect_used))]

pub mod code;
pub mod config;
pub mod grid;
pub mod jpeg;
pub mod pattern;
pub mod report;
pub mod retry;
pub mod source;
pub mod v4l2;

use crate::config::Config;
use crate::report::CameraCore;
use crate::source::{Camera, Event, TestPattern};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::{CameraInfo, CompressedImage};
use ros_plumbing::Params;
use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;
use tokio::sync::mpsc;

/// The node's description and parameters.
pub fn spec() -> ros_plumbing::NodeSpec {
    let mut params = config::params();
    params.push(ros_plumbing::diagnostics::diagnostics_period_param());
    ros_plumbing::NodeSpec {
        name: "camera_node",
        description: "a V4L2 webcam (MJPEG passed through, YUYV encoded) or a test pattern -> camera/image_raw/compressed (JPEG) and camera/camera_info",
        usage: "",
        params,
    }
}

/// Where the loop's results go.
pub trait Outputs {
    /// Publish on `camera/image_raw/compressed`.
    fn image(&self, msg: CompressedImage);
    /// Publish on `camera/camera_info`.
    fn camera_info(&self, msg: CameraInfo);
    /// Publish a `diagnostics` report.
    fn diagnostics(&self, status: DiagnosticStatus);
}

/// Frames waiting for the loop; a frame that finds it full is dropped (and counted).
pub const QUEUE: usize = 2;

/// The capture thread ([`source::capture`]) and its stop flag.
pub struct Capture {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Capture {
    /// Start capturing from `config`'s device (the test pattern for `test`) on a thread
    /// of its own; its events go to the returned receiver.
    pub fn start(config: &Config) -> std::io::Result<(Capture, mpsc::Receiver<Event>)> {
        let (tx, rx) = mpsc::channel(QUEUE);
        let stop = Arc::new(AtomicBool::new(false));
        let mut camera: Box<dyn Camera + Send> = if config.is_test() {
            Box::new(TestPattern::new(config))
        } else {
            Box::new(v4l2::V4l2Camera::new(config))
        };
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("capture".into())
            .spawn(move || {
                source::capture(camera.as_mut(), retry::RETRY, &flag, |e| {
                    match tx.try_send(e) {
                        Ok(()) => true,
                        // a failure or open is never lost: wait for room
                        Err(mpsc::error::TrySendError::Full(
                            e @ (Event::Opened(_) | Event::Failed { .. }),
                        )) => tx.blocking_send(e).is_ok(),
                        Err(mpsc::error::TrySendError::Full(_)) => false,
                        Err(mpsc::error::TrySendError::Closed(_)) => {
                            flag.store(true, Ordering::Relaxed);
                            false
                        }
                    }
                });
            })?;
        Ok((
            Capture {
                stop,
                thread: Some(thread),
            },
            rx,
        ))
    }

    /// Stop the thread and wait for it (at most one read: 2 s for a V4L2 camera).
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                log::error!("the capture thread panicked");
            }
        }
    }
}

/// What [`run`] works with.
pub struct Handles<'a, O, S> {
    /// the node's core
    pub core: CameraCore,
    /// where results go
    pub outputs: &'a O,
    /// the node's parameters (the diagnostics period)
    pub params: Params,
    /// the capture's events
    pub events: mpsc::Receiver<Event>,
    /// resolves when the node is to stop
    pub shutdown: S,
}

/// The loop: each capture event through the core, its messages out; the diagnostics
/// entry every `diagnostics_period`. Runs until `shutdown` resolves or the capture ends.
pub async fn run<O: Outputs>(h: Handles<'_, O, impl Future<Output = ()>>) {
    let Handles {
        mut core,
        outputs,
        params,
        mut events,
        shutdown,
    } = h;
    let period = ros_plumbing::diagnostics::diagnostics_period;
    let mut ticker = tokio::time::interval(period(&params));
    let mut param_changes = params.subscribe();
    tokio::pin!(shutdown);
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            _ = ticker.tick() => outputs.diagnostics(core.report(Instant::now())),
            Ok(()) = param_changes.changed() => ticker = tokio::time::interval(period(&params)),
            event = events.recv() => match event {
                None => break,
                Some(e) => if let Some(p) = core.on_event(e) {
                    outputs.image(p.image);
                    outputs.camera_info(p.info);
                },
            },
        }
    }
}
