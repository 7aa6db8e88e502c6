//! The twin's camera: MuJoCo's offscreen renderer (EGL, Mesa's software rasteriser where
//! there is no GPU) on a thread of its own, fed snapshots of the simulation, so that a
//! frame being drawn never holds up the physics or the servo link.
//!
//! The physics thread [`offers`](CameraFeed::offer) a snapshot (MuJoCo's visual copy of
//! its data, with the frame's stamp) when a frame is due; the camera thread renders the
//! newest one, encodes it to JPEG and hands it on. A snapshot offered while the previous
//! one is still waiting replaces it, and is counted as dropped.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

use eezybot_msgs::sensor_msgs::{CameraInfo, CompressedImage};
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;

/// The camera model's name in the generated MJCF.
pub const CAMERA: &str = "scene";

/// A frame for the camera thread: the simulation's visual state and its stamp.
struct Shot {
    data: MjData<Arc<MjModel>>,
    stamp: Time,
    fresh: bool,
}

struct Shared {
    shot: Mutex<Shot>,
    wake: Condvar,
    stop: AtomicBool,
    dropped: AtomicU64,
    published: AtomicU64,
}

/// The camera thread and what it shares with the physics.
pub struct CameraFeed {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

/// What the camera thread needs besides the model.
#[derive(Clone, Debug)]
pub struct CameraSettings {
    /// Image size (px).
    pub width: u32,
    /// Image height (px).
    pub height: u32,
    /// Vertical field of view (deg), for the camera info's pinhole model.
    pub fovy_deg: f64,
    /// JPEG quality.
    pub jpeg_quality: u8,
    /// `header.frame_id` of the images.
    pub frame_id: String,
}

impl CameraFeed {
    /// Starts the camera thread: its renderer is made there (an EGL context belongs to
    /// its thread), and an error making it (no EGL, no offscreen buffer) comes back
    /// here. `publish` gets each frame.
    pub fn start(
        model: Arc<MjModel>,
        settings: CameraSettings,
        publish: impl FnMut(CompressedImage, CameraInfo) + Send + 'static,
    ) -> Result<CameraFeed, String> {
        let shared = Arc::new(Shared {
            shot: Mutex::new(Shot {
                data: MjData::new(model.clone()),
                stamp: Time::ZERO,
                fresh: false,
            }),
            wake: Condvar::new(),
            stop: AtomicBool::new(false),
            dropped: AtomicU64::new(0),
            published: AtomicU64::new(0),
        });
        let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel(1);
        let thread_shared = shared.clone();
        let thread = std::thread::Builder::new()
            .name("twin camera".into())
            .spawn(
                move || match scene_renderer(&model, settings.width, settings.height) {
                    Ok(r) => {
                        let _ = ready_tx.send(Ok(()));
                        render_loop(r, &thread_shared, &settings, publish);
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                    }
                },
            )
            .map_err(|e| e.to_string())?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(CameraFeed {
                shared,
                thread: Some(thread),
            }),
            Ok(Err(e)) => {
                let _ = thread.join();
                Err(e)
            }
            Err(_) => Err("the camera thread ended before its renderer was made".into()),
        }
    }

    /// Offers the simulation's state at `stamp` as the next frame.
    pub fn offer(&self, data: &MjData<Arc<MjModel>>, stamp: Time) {
        if let Ok(mut shot) = self.shared.shot.lock() {
            if shot.fresh {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
            }
            if data.copy_visual_to(&mut shot.data).is_ok() {
                shot.stamp = stamp;
                shot.fresh = true;
                self.shared.wake.notify_one();
            }
        }
    }

    /// Frames published, and snapshots dropped because the camera was still busy.
    pub fn counts(&self) -> (u64, u64) {
        (
            self.shared.published.load(Ordering::Relaxed),
            self.shared.dropped.load(Ordering::Relaxed),
        )
    }
}

impl Drop for CameraFeed {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.shared.wake.notify_one();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// An offscreen renderer of the model's camera [`CAMERA`] at `width` × `height` (on the
/// calling thread: its EGL context belongs to it).
pub fn scene_renderer(model: &MjModel, width: u32, height: u32) -> Result<MjRenderer, String> {
    let camera = model
        .name_to_id(MjtObjBase::mjOBJ_CAMERA, CAMERA)
        .ok_or_else(|| format!("the model has no camera `{CAMERA}`"))?;
    MjRenderer::builder()
        .width(width)
        .height(height)
        .camera(MjvCamera::new_fixed(camera))
        .build(model)
        .map_err(|e| format!("the camera's offscreen renderer: {e}"))
}

/// The camera info of an ideal pinhole camera of `fovy_deg` (square pixels, no
/// distortion), as MuJoCo renders.
pub fn pinhole(width: u32, height: u32, fovy_deg: f64, header: Header) -> CameraInfo {
    let f = f64::from(height) / 2.0 / (fovy_deg.to_radians() / 2.0).tan();
    let (cx, cy) = (f64::from(width) / 2.0, f64::from(height) / 2.0);
    CameraInfo {
        header,
        height,
        width,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: [f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        ..CameraInfo::default()
    }
}

fn render_loop(
    mut renderer: MjRenderer,
    shared: &Shared,
    settings: &CameraSettings,
    mut publish: impl FnMut(CompressedImage, CameraInfo),
) {
    loop {
        let stamp = {
            let Ok(mut shot) = shared.shot.lock() else {
                return;
            };
            while !shot.fresh && !shared.stop.load(Ordering::Relaxed) {
                shot = match shared.wake.wait(shot) {
                    Ok(s) => s,
                    Err(_) => return,
                };
            }
            if shared.stop.load(Ordering::Relaxed) {
                return;
            }
            shot.fresh = false;
            if let Err(e) = renderer.sync_data(&mut shot.data) {
                log::error!("twin camera: {e}");
                return;
            }
            shot.stamp
        };
        if let Err(e) = renderer.render() {
            log::error!("twin camera: {e}");
            return;
        }
        let Some(rgb) = renderer.rgb_flat() else {
            return;
        };
        let (w, h) = (settings.width as usize, settings.height as usize);
        match camera_node::jpeg::encode_rgb(rgb, w, h, settings.jpeg_quality) {
            Ok(jpeg) => {
                let header = Header {
                    stamp,
                    frame_id: settings.frame_id.clone(),
                };
                let info = pinhole(
                    settings.width,
                    settings.height,
                    settings.fovy_deg,
                    header.clone(),
                );
                publish(
                    CompressedImage {
                        header,
                        format: "jpeg".into(),
                        data: jpeg,
                    },
                    info,
                );
                shared.published.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => log::warn!("twin camera: {e}"),
        }
    }
}
