//! The calibration wizard's ROS side ([`crate::CalibrationControl`]): the arm taken
//! from compute_ik's controllers and given back through its controller manager
//! (`calibration` activated by a strict `switch_controller`, the lease renewed while
//! calibrating), `servo_angles` while calibrating (the publisher exists only then, so
//! that serial_node and `ros2 topic info` see one commander the rest of the time), and
//! saving: the file written atomically ([`arm_config_file::write_calibration`], off the
//! event loop), then `arm_config` set on compute_ik and every serial_node running, by name
//! (`ik_node`, `servo_nodes`).

use crate::calibrate::SaveOutcome;
use crate::{CalibrationControl, SaveJob};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use futures::future::LocalBoxFuture;
use ros_plumbing::controller_manager::ControllerManager;
use ros_plumbing::remote_params::RemoteParameters;
use ros_plumbing::{topics, ParameterValue, RosNode, TopicPublisher};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// How long a node has to answer a parameter request.
pub const PARAM_TIMEOUT: Duration = Duration::from_secs(3);
/// How long the new `servo_angles` publisher waits for serial_node's subscription.
pub const MATCH_TIMEOUT: Duration = Duration::from_secs(2);
/// How long writing the file may take.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// The controller that drives the servos while calibrating.
pub const CALIBRATION: &str = "calibration";
/// How often the lease on `calibration` is renewed (compute_ik gives the arm back after
/// its `calibration_lease`, 10 s, without a word from us).
pub const LEASE_RENEWAL: Duration = Duration::from_secs(2);

/// Where the wizard saves: `calibration_file`, else `arm_config`, else
/// `$XDG_CONFIG_HOME/eezybot/arm.yaml` (`~/.config/eezybot/arm.yaml`).
pub fn calibration_path(calibration_file: &str, arm_config: &str) -> PathBuf {
    for p in [calibration_file, arm_config] {
        if !p.trim().is_empty() {
            return p.into();
        }
    }
    let var = |v: &str| std::env::var_os(v).filter(|s| !s.is_empty());
    let config = match (var("XDG_CONFIG_HOME"), var("HOME")) {
        (Some(x), _) => PathBuf::from(x),
        (None, Some(h)) => Path::new(&h).join(".config"),
        (None, None) => PathBuf::from("."),
    };
    config.join("eezybot").join("arm.yaml")
}

/// Write `job`'s calibration to `path` (made from the shipped configuration first when
/// it does not exist): the file written and its backup.
pub fn write(path: &Path, job: &SaveJob) -> Result<(String, Option<String>), String> {
    if !path.exists() {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)
                .map_err(|e| format!("cannot make {}: {e}", dir.display()))?;
        }
        std::fs::write(path, eezybot_kinematics::SHIPPED_ARM_YAML)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        log::info!(
            "calibration: {} did not exist; made from the shipped configuration",
            path.display()
        );
    }
    let saved = arm_config_file::write_calibration(path, &job.servos, job.leader.as_ref())
        .map_err(|e| e.to_string())?;
    Ok((
        saved.path.display().to_string(),
        Some(saved.backup.display().to_string()),
    ))
}

/// The wizard's ROS side on a node.
pub struct RosCalibration<'n, 'r> {
    node: &'n RefCell<&'r mut RosNode>,
    path: PathBuf,
    clients: RefCell<BTreeMap<String, std::rc::Rc<RemoteParameters>>>,
    servo_angles: RefCell<Option<TopicPublisher<JointState>>>,
    /// the name compute_ik runs under
    compute_ik: String,
    /// compute_ik's controller manager (made now, so that it is matched before use)
    manager: Result<std::sync::Arc<ControllerManager>, String>,
    /// renews the lease on `calibration` while we hold it
    lease: RefCell<Option<tokio::task::JoinHandle<()>>>,
}

impl Drop for RosCalibration<'_, '_> {
    fn drop(&mut self) {
        if let Some(renewal) = self.lease.borrow_mut().take() {
            renewal.abort();
        }
    }
}

impl<'n, 'r> RosCalibration<'n, 'r> {
    /// On `node`, saving to `path`; compute_ik is the node named `compute_ik` (its
    /// parameter client is made now, so that it is matched before the wizard starts).
    pub fn new(node: &'n RefCell<&'r mut RosNode>, path: PathBuf, compute_ik: &str) -> Self {
        let manager = ControllerManager::new(&mut node.borrow_mut(), compute_ik)
            .map(std::sync::Arc::new)
            .map_err(|e| format!("no client of {compute_ik}'s controller manager: {e}"));
        if let Err(e) = &manager {
            log::warn!("calibration: {e}");
        }
        let c = RosCalibration {
            node,
            path,
            clients: RefCell::new(BTreeMap::new()),
            servo_angles: RefCell::new(None),
            compute_ik: compute_ik.to_string(),
            manager,
            lease: RefCell::new(None),
        };
        if let Err(e) = c.client(compute_ik) {
            log::warn!("calibration: {e}");
        }
        c
    }

    /// Where the wizard saves.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn client(&self, name: &str) -> Result<std::rc::Rc<RemoteParameters>, String> {
        if let Some(c) = self.clients.borrow().get(name) {
            return Ok(c.clone());
        }
        let c = RemoteParameters::new(&mut self.node.borrow_mut(), name)
            .map_err(|e| format!("no parameter client for {name}: {e}"))?;
        let c = std::rc::Rc::new(c);
        self.clients
            .borrow_mut()
            .insert(name.to_string(), c.clone());
        Ok(c)
    }

    /// Wait until `name`'s parameter services are matched (a request sent before is
    /// lost), at most `timeout`. The node stays borrowed meanwhile: only for a caller
    /// that runs nothing else on it then (the command line; the panel makes its clients
    /// long before they are used, see [`CalibrationControl::prepare`]).
    #[allow(clippy::await_holding_refcell_ref)]
    pub async fn wait_ready(&self, name: &str, timeout: Duration) -> Result<(), String> {
        let client = self.client(name)?;
        let ros = self.node.borrow();
        client.wait(&ros, timeout).await.map_err(|e| e.to_string())
    }

    /// Take the arm: `calibration` activated, whoever held the joints deactivated, in
    /// one strict switch; then the lease renewed every [`LEASE_RENEWAL`] until
    /// [`Self::give_back`].
    async fn take_arm(&self) -> Result<(), String> {
        let manager = self.manager.clone()?;
        let active = within(manager.active(), &manager).await?;
        if !active.iter().any(|n| n == CALIBRATION) {
            let holders: Vec<&str> = active.iter().map(String::as_str).collect();
            within(manager.switch(&[CALIBRATION], &holders), &manager)
                .await
                .map_err(|why| {
                    format!("{} refused to switch to calibration: {why}", manager.name())
                })?;
        }
        let renewing = manager.clone();
        let renewal = tokio::spawn(async move {
            loop {
                tokio::time::sleep(LEASE_RENEWAL).await;
                if let Err(e) = renewing.list().await {
                    log::warn!("calibration: the lease was not renewed: {e}");
                }
            }
        });
        if let Some(old) = self.lease.borrow_mut().replace(renewal) {
            old.abort();
        }
        Ok(())
    }

    /// Give the arm back: `calibration` deactivated (compute_ik takes the arm where
    /// `servo_state` says it is). Done already when the lease ran out.
    async fn give_back(&self) -> Result<(), String> {
        if let Some(renewal) = self.lease.borrow_mut().take() {
            renewal.abort();
        }
        let manager = self.manager.clone()?;
        let active = within(manager.active(), &manager).await?;
        if !active.iter().any(|n| n == CALIBRATION) {
            return Ok(());
        }
        within(manager.switch(&[], &[CALIBRATION]), &manager).await
    }

    async fn set(&self, name: &str, param: &str, value: ParameterValue) -> Result<(), String> {
        let client = self.client(name)?;
        match tokio::time::timeout(PARAM_TIMEOUT, client.set(param, value)).await {
            Ok(r) => r,
            Err(_) => Err(format!(
                "{} did not answer within {:.0} s",
                client.node_name(),
                PARAM_TIMEOUT.as_secs_f64()
            )),
        }
    }

    /// Make the `servo_angles` publisher and wait (a little) for serial_node to match
    /// it, so that the first command is not sent before anyone hears it.
    async fn open_servo_angles(&self) -> Result<(), String> {
        if self.servo_angles.borrow().is_none() {
            let p = self
                .node
                .borrow_mut()
                .publish_on(&topics::SERVO_ANGLES)
                .map_err(|e| format!("cannot publish servo_angles: {e}"))?;
            *self.servo_angles.borrow_mut() = Some(p);
        }
        let start = tokio::time::Instant::now();
        loop {
            let matched = {
                let ros = self.node.borrow();
                self.servo_angles
                    .borrow()
                    .as_ref()
                    .map(|p| p.get_subscription_count(ros.node()))
                    .unwrap_or(0)
            };
            if matched > 0 {
                return Ok(());
            }
            if start.elapsed() > MATCH_TIMEOUT {
                return Err(format!(
                    "no subscriber of servo_angles within {:.0} s: is serial_node running?",
                    MATCH_TIMEOUT.as_secs_f64()
                ));
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
}

/// `call`, or its failure when `manager` does not answer within [`PARAM_TIMEOUT`].
async fn within<T>(
    call: impl std::future::Future<Output = Result<T, String>>,
    manager: &ControllerManager,
) -> Result<T, String> {
    tokio::time::timeout(PARAM_TIMEOUT, call)
        .await
        .unwrap_or_else(|_| {
            Err(format!(
                "{} did not answer within {:.0} s",
                manager.name(),
                PARAM_TIMEOUT.as_secs_f64()
            ))
        })
}

impl CalibrationControl for RosCalibration<'_, '_> {
    fn set_calibrating(&self, on: bool) -> LocalBoxFuture<'_, Result<(), String>> {
        Box::pin(async move {
            let r = if on {
                self.open_servo_angles().await?;
                self.take_arm().await
            } else {
                self.give_back().await
            };
            if !on || r.is_err() {
                // compute_ik commands again (or never stopped): one commander only
                *self.servo_angles.borrow_mut() = None;
            }
            r
        })
    }

    fn save(&self, job: SaveJob) -> LocalBoxFuture<'_, SaveOutcome> {
        Box::pin(async move {
            let path = self.path.clone();
            let j = job.clone();
            let written = match tokio::time::timeout(
                WRITE_TIMEOUT,
                tokio::task::spawn_blocking(move || write(&path, &j)),
            )
            .await
            {
                Ok(Ok(r)) => r,
                Ok(Err(e)) => Err(format!("the writer failed: {e}")),
                Err(_) => Err(format!(
                    "writing {} took over {:.0} s",
                    self.path.display(),
                    WRITE_TIMEOUT.as_secs_f64()
                )),
            };
            let mut outcome = SaveOutcome {
                written,
                applied: vec![],
                failed: vec![],
            };
            let Ok((file, _)) = outcome.written.clone() else {
                return outcome;
            };
            // this node's own: what `ros2 param get` shows (the panel's checks use the
            // geometry and limits, which a calibration does not change)
            self.node
                .borrow()
                .params()
                .set("arm_config", ParameterValue::String(file.clone()));
            outcome
                .applied
                .push(self.node.borrow().resolver().node_name().to_string());
            let mut nodes = job.nodes.clone();
            if !nodes.contains(&self.compute_ik) {
                nodes.insert(0, self.compute_ik.clone());
            }
            for name in nodes {
                match self
                    .set(&name, "arm_config", ParameterValue::String(file.clone()))
                    .await
                {
                    Ok(()) => outcome.applied.push(name),
                    Err(e) => outcome.failed.push(format!("{name}: {e}")),
                }
            }
            if job.end_calibrating {
                if let Err(e) = self.set_calibrating(false).await {
                    outcome
                        .failed
                        .push(format!("{}: calibrating not ended: {e}", self.compute_ik));
                }
            }
            outcome
        })
    }

    fn prepare(&self, nodes: &[String]) {
        for name in nodes {
            if !self.clients.borrow().contains_key(name) {
                if let Err(e) = self.client(name) {
                    log::warn!("calibration: {e}");
                }
            }
        }
    }

    fn servo_angles(&self, deg: [f64; 4], stamp: Time) {
        let p = self.servo_angles.borrow();
        let Some(p) = p.as_ref() else {
            log::warn!("calibration: servo_angles not published (no publisher: not calibrating)");
            return;
        };
        p.publish(JointState {
            header: Header {
                stamp,
                frame_id: String::new(),
            },
            name: eezybot_kinematics::ServoId::ALL
                .iter()
                .map(|s| s.name().to_string())
                .collect(),
            position: deg.iter().map(|d| d.to_radians()).collect(),
            velocity: vec![],
            effort: vec![],
        });
    }
}
