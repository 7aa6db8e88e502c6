//! The twin as a ROS node: the physics on a thread of its own behind the pseudo-terminal
//! (serial_node's [`pty::serve`]), the device's pulses driving the servos, the simulation
//! kept up with the wall clock; `twin/joint_states`, the cube's tf frame and the
//! diagnostics from that thread, the camera from its own ([`crate::camera`]).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use eezybot_kinematics::ArmConfig;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{Transform, TransformStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::tf2_msgs::TFMessage;
use eezybot_msgs::Time;
use ros_plumbing::diagnostics::{status, DiagnosticsPublisher};
use ros_plumbing::{topics, RosNode, Shutdown, TopicPublisher};
use serial_node::pty;
use servo_protocol::device::{Device, DeviceConfig};

use crate::camera::{CameraFeed, CameraSettings};
use crate::sim::Sim;
use crate::Config;

/// The URDF the twin is made from.
pub const URDF: &str = include_str!("../../../urdf/eezybot.urdf");

/// The cube's tf frame (child of `base_link`).
pub const CUBE_FRAME: &str = "cube";

/// Physics caught up per tick at most: a host too slow for real time lags (and says
/// so) rather than spiral.
const MAX_CATCH_UP_S: f64 = 0.1;

/// Sets up the twin and runs it until `shutdown`, or until the simulation fails (an
/// error: the process ends with it, its terminal closed).
pub async fn serve(node: &mut RosNode, shutdown: Shutdown) -> anyhow::Result<()> {
    let params = node.params().clone();
    let config = Config::from_params(&params).map_err(anyhow::Error::msg)?;
    let arm = ArmConfig::load_or_shipped(&config.arm_config)?;
    let link = if config.link.is_empty() {
        pty::twin_link(u32::from(node.domain_id()), node.resolver().namespace())
    } else {
        PathBuf::from(&config.link)
    };
    let sim = Sim::new(URDF, &arm, &config.scene)?;
    let outputs = Outputs {
        joints: node.publish_on(&topics::TWIN_JOINT_STATES)?,
        tf: node.publish_on(&topics::TF)?,
        diagnostics: node.diagnostics()?,
        diag_name: format!("{}: physics twin", node.resolver().node_name()),
    };
    let camera = if config.camera_fps == 0 {
        None
    } else {
        let image = node.publish_on(&topics::TWIN_CAMERA_IMAGE)?;
        let info = node.publish_on(&topics::TWIN_CAMERA_INFO)?;
        let settings = CameraSettings {
            width: config.scene.image_size.0,
            height: config.scene.image_size.1,
            fovy_deg: config.scene.camera_fovy_deg,
            jpeg_quality: config.jpeg_quality,
            frame_id: "twin_camera".into(),
        };
        match CameraFeed::start(sim.mj_model(), settings, move |img, inf| {
            image.publish(img);
            info.publish(inf);
        }) {
            Ok(feed) => Some(feed),
            Err(e) => {
                log::error!("twin: no camera: {e} (the physics runs without it)");
                None
            }
        }
    };
    log::info!(
        "{} ready in ROS domain {}: the arm in MuJoCo, driven by {}, publishing {} and the tf frame `{CUBE_FRAME}`{}",
        node.resolver().node_fqn(),
        node.domain_id(),
        if !config.pulse_events.is_empty() {
            format!("the servo pins of the board in simavr ({}), in lock-step with its clock", config.pulse_events)
        } else if config.link.is_empty() {
            format!("{} (serial_node port:={})", link.display(), serial_node::TWIN_PORT)
        } else {
            format!("{} (serial_node port:={})", link.display(), link.display())
        },
        node.resolve(&topics::TWIN_JOINT_STATES)?,
        if camera.is_some() {
            format!(", camera {}x{} at {} fps on {}", config.scene.image_size.0, config.scene.image_size.1, config.camera_fps, node.resolve(&topics::TWIN_CAMERA_IMAGE)?)
        } else {
            String::new()
        }
    );
    let stop = Arc::new(AtomicBool::new(false));
    let (done_tx, done_rx) = tokio::sync::oneshot::channel();
    let period = ros_plumbing::diagnostics::diagnostics_period(&params);
    let thread_stop = stop.clone();
    let link_text = if config.pulse_events.is_empty() {
        link.to_string_lossy().into_owned()
    } else {
        format!("the pins of {} (lock-step)", config.pulse_events)
    };
    let physics = std::thread::Builder::new()
        .name("twin physics".into())
        .spawn(move || {
            let events = config.pulse_events.clone();
            let mut run = Physics::new(sim, camera, outputs, &config, period, link_text.clone());
            let result = if events.is_empty() {
                let device = Device::new(DeviceConfig::default());
                pty::serve("twin", &link_text, device, &thread_stop, |device, now| {
                    run.tick(device, now)
                })
                .map_err(|e| e.to_string())
            } else {
                follow_events(&events, &thread_stop, &mut run)
            };
            if let Err(e) = &result {
                run.report_failure(e);
            }
            let _ = done_tx.send(result);
        })?;
    let result = tokio::select! {
        _ = shutdown => Ok(()),
        done = done_rx => match done {
            Ok(Ok(())) => Ok(()),
            Ok(Err(e)) => Err(anyhow::anyhow!("{e}")),
            Err(_) => Err(anyhow::anyhow!("the physics thread ended")),
        },
    };
    stop.store(true, Ordering::Relaxed);
    if physics.join().is_err() {
        log::error!("twin: the physics thread panicked");
    }
    result
}

struct Outputs {
    joints: TopicPublisher<JointState>,
    tf: TopicPublisher<TFMessage>,
    diagnostics: DiagnosticsPublisher,
    diag_name: String,
}

/// The physics thread's state between ticks.
struct Physics {
    sim: Sim,
    camera: Option<CameraFeed>,
    out: Outputs,
    /// the wall clock (ns since the epoch) at simulated time 0
    epoch_ns: i64,
    state_period: f64,
    frame_period: Option<f64>,
    diag_period: f64,
    next_state: f64,
    next_frame: f64,
    next_diag: f64,
    /// (wall, simulated) time at the last diagnostics report
    last_report: (f64, f64),
    /// the host was too slow for real time once (said once)
    behind_reported: bool,
    link: String,
}

impl Physics {
    fn new(
        sim: Sim,
        camera: Option<CameraFeed>,
        out: Outputs,
        config: &Config,
        diag: Duration,
        link: String,
    ) -> Physics {
        let epoch_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(0));
        Physics {
            sim,
            camera,
            out,
            epoch_ns,
            state_period: 1.0 / config.state_rate_hz,
            frame_period: (config.camera_fps > 0).then(|| 1.0 / f64::from(config.camera_fps)),
            diag_period: diag.as_secs_f64(),
            next_state: 0.0,
            next_frame: 0.0,
            next_diag: 0.0,
            last_report: (0.0, 0.0),
            behind_reported: false,
            link,
        }
    }

    /// The stamp of simulated time `t`.
    fn stamp(&self, t: f64) -> Time {
        Time::from_nanos(self.epoch_ns + (t * 1e9) as i64)
    }

    fn tick(&mut self, device: &Device, now: Duration) -> Result<(), String> {
        self.sim
            .set_pulses_us(device.pulses().map(|t| f64::from(t) / 2.0));
        let now = now.as_secs_f64();
        let mut budget = (MAX_CATCH_UP_S / self.sim.timestep()) as u32;
        while self.sim.time() < now && budget > 0 {
            self.sim.step().map_err(|e| e.to_string())?;
            budget -= 1;
            self.after_step();
        }
        if budget == 0 && !self.behind_reported {
            log::warn!(
                "twin: the simulation is behind real time ({:.2} s simulated at {now:.2} s)",
                self.sim.time()
            );
            self.behind_reported = true;
        }
        self.maybe_report(now);
        Ok(())
    }

    /// After a physics step: the state and a camera frame when they are due.
    fn after_step(&mut self) {
        let t = self.sim.time();
        if t >= self.next_state {
            self.publish_state(t);
            self.next_state = t + self.state_period;
        }
        if let (Some(period), Some(camera)) = (self.frame_period, &self.camera) {
            if t >= self.next_frame {
                camera.offer(self.sim.data(), self.stamp(t));
                self.next_frame = (self.next_frame + period).max(t);
            }
        }
    }

    fn maybe_report(&mut self, now: f64) {
        if now >= self.next_diag {
            self.report(now);
            self.next_diag = now + self.diag_period;
        }
    }

    fn publish_state(&self, t: f64) {
        let header = Header {
            stamp: self.stamp(t),
            frame_id: String::new(),
        };
        let joints = self.sim.joint_positions();
        self.out.joints.publish(JointState {
            header: header.clone(),
            name: joints.iter().map(|(n, _)| n.to_string()).collect(),
            position: joints.iter().map(|(_, q)| *q).collect(),
            velocity: self.sim.joint_velocities(),
            effort: Vec::new(),
        });
        let (p, q) = self.sim.cube_pose();
        let mut transform = Transform::default();
        transform.translation.x = p.x;
        transform.translation.y = p.y;
        transform.translation.z = p.z;
        transform.rotation.x = q.i;
        transform.rotation.y = q.j;
        transform.rotation.z = q.k;
        transform.rotation.w = q.w;
        self.out.tf.publish(TFMessage {
            transforms: vec![TransformStamped {
                header: Header {
                    stamp: header.stamp,
                    frame_id: "base_link".into(),
                },
                child_frame_id: CUBE_FRAME.into(),
                transform,
            }],
        });
    }

    fn report(&mut self, now: f64) {
        let t = self.sim.time();
        let (wall0, sim0) = self.last_report;
        let factor = if now > wall0 {
            (t - sim0) / (now - wall0)
        } else {
            0.0
        };
        self.last_report = (now, t);
        let loops = self.sim.loop_errors().into_iter().fold(0.0, f64::max);
        let targets = self.sim.horn_targets();
        let horns = self.sim.horns();
        let deg = |v: [f64; 4]| v.map(|r| format!("{:.1}", r.to_degrees())).join(", ");
        let (cube, _) = self.sim.cube_pose();
        let mut values = vec![
            ("link", self.link.clone()),
            ("sim_time_s", format!("{t:.3}")),
            ("real_time_factor", format!("{factor:.2}")),
            ("loop_error_mm", format!("{:.3}", loops * 1e3)),
            ("horns_deg", deg(horns)),
            (
                "targets_deg",
                targets
                    .map(|t| t.map_or("limp".to_string(), |r| format!("{:.1}", r.to_degrees())))
                    .join(", "),
            ),
            (
                "cube_m",
                format!("{:.3}, {:.3}, {:.3}", cube.x, cube.y, cube.z),
            ),
        ];
        if let Some(c) = &self.camera {
            let (published, dropped) = c.counts();
            values.push(("camera_frames", published.to_string()));
            values.push(("camera_dropped", dropped.to_string()));
        }
        let (level, message) = if factor < 0.95 && now > 2.0 * self.diag_period {
            (
                DiagnosticStatus::WARN,
                format!("behind real time: {factor:.2}x"),
            )
        } else {
            (DiagnosticStatus::OK, "running".to_string())
        };
        self.out.diagnostics.publish(vec![status(
            level,
            &self.out.diag_name,
            "eezybot_twin",
            &message,
            &values,
        )]);
    }

    fn report_failure(&self, why: &str) {
        log::error!("twin: stopped: {why}");
        self.out.diagnostics.publish(vec![status(
            DiagnosticStatus::ERROR,
            &self.out.diag_name,
            "eezybot_twin",
            &format!("stopped: {why}"),
            &[
                ("link", self.link.clone()),
                ("sim_time_s", format!("{:.3}", self.sim.time())),
            ],
        )]);
    }
}

/// Follows a servo_sim event file ([`crate::lockstep`]) until `stop`: the lines as they
/// are appended (a partial last line waits for its end), the physics advanced to each
/// event's simulated time; while the file does not grow, the twin waits with the board.
fn follow_events(path: &str, stop: &AtomicBool, run: &mut Physics) -> Result<(), String> {
    use std::io::Read;
    use twin_model::pulses::BoardEvent;
    let mut file = std::fs::File::open(path).map_err(|e| format!("{path}: {e}"))?;
    let mut lockstep = crate::lockstep::Lockstep::new();
    let mut pending = String::new();
    let mut buf = vec![0u8; 1 << 16];
    let started = std::time::Instant::now();
    while !stop.load(Ordering::Relaxed) {
        let n = file.read(&mut buf).map_err(|e| format!("{path}: {e}"))?;
        if n == 0 {
            // the board has not run further yet (a file gives no wake-up: look again soon)
            std::thread::sleep(Duration::from_millis(2));
            run.maybe_report(started.elapsed().as_secs_f64());
            continue;
        }
        pending.push_str(&String::from_utf8_lossy(&buf[..n]));
        let complete = pending.rfind('\n').map_or(0, |i| i + 1);
        for line in pending[..complete].lines() {
            if let Some(event) = BoardEvent::parse(line) {
                lockstep
                    .apply(&mut run.sim, event)
                    .map_err(|e| e.to_string())?;
                if let Some(epoch) = lockstep.epoch_ns() {
                    run.epoch_ns = epoch;
                }
                // (the board's clock line comes every simulated millisecond, a physics
                // step: an event advances the physics by one step at most)
                run.after_step();
            }
        }
        pending.drain(..complete);
        run.maybe_report(started.elapsed().as_secs_f64());
    }
    Ok(())
}
