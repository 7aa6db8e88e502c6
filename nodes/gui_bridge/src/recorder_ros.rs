//! The recording card's ROS side ([`crate::RecorderControl`]): the recorder node's
//! `task` parameter set through its parameter services, and its Trigger services
//! `<recorder>/start_episode`, `save_episode`, `discard_episode` called, by the node's
//! name (`recorder_node`). The clients are made when the panel starts, so that they are
//! matched long before a button is pressed (a request sent before would be lost, and
//! end as a call without an answer). Every call is bounded in time.

use crate::recording::{RecordOp, RecordWork};
use crate::RecorderControl;
use futures::future::LocalBoxFuture;
use ros_plumbing::remote_params::RemoteParameters;
use ros_plumbing::trigger::TriggerClient;
use ros_plumbing::{ParameterValue, RosNode};
use std::time::Duration;

/// How long the recorder has to answer a parameter set.
pub const PARAM_TIMEOUT: Duration = Duration::from_secs(3);
/// How long it has to start or discard an episode.
pub const CALL_TIMEOUT: Duration = Duration::from_secs(5);
/// How long it has to save one (it writes the episode out first).
pub const SAVE_TIMEOUT: Duration = Duration::from_secs(30);

/// How long the recorder has to answer `op`.
pub fn timeout(op: RecordOp) -> Duration {
    match op {
        RecordOp::Save => SAVE_TIMEOUT,
        RecordOp::Start | RecordOp::Discard => CALL_TIMEOUT,
    }
}

/// The clients of one recorder node.
pub struct RosRecorder {
    node: String,
    params: Result<RemoteParameters, String>,
    /// start, save, discard
    services: [Result<TriggerClient, String>; 3],
}

impl RosRecorder {
    /// The clients of the recorder node named `recorder` (in our namespace, or
    /// absolute); one that cannot be made is logged, and its calls fail saying why.
    pub fn new(ros: &mut RosNode, recorder: &str) -> RosRecorder {
        let params = RemoteParameters::new(ros, recorder)
            .map_err(|e| format!("no parameter client for {recorder}: {e}"));
        let services = [RecordOp::Start, RecordOp::Save, RecordOp::Discard].map(|op| {
            let name = format!("{recorder}/{}", op.service());
            TriggerClient::new(ros, &name).map_err(|e| format!("no client of {name}: {e}"))
        });
        for e in services.iter().filter_map(|s| s.as_ref().err()) {
            log::warn!("record: {e}");
        }
        if let Err(e) = &params {
            log::warn!("record: {e}");
        }
        RosRecorder {
            node: recorder.to_string(),
            params,
            services,
        }
    }

    fn service(&self, op: RecordOp) -> Result<&TriggerClient, String> {
        let i = match op {
            RecordOp::Start => 0,
            RecordOp::Save => 1,
            RecordOp::Discard => 2,
        };
        self.services[i].as_ref().map_err(Clone::clone)
    }

    async fn set_task(&self, task: &str) -> Result<(), String> {
        let params = self.params.as_ref().map_err(Clone::clone)?;
        let set = params.set("task", ParameterValue::String(task.to_string()));
        match tokio::time::timeout(PARAM_TIMEOUT, set).await {
            Ok(r) => r.map_err(|e| format!("the task was not set: {e}")),
            Err(_) => Err(format!(
                "the task was not set: {} did not answer within {:.0} s",
                params.node_name(),
                PARAM_TIMEOUT.as_secs_f64()
            )),
        }
    }
}

impl RecorderControl for RosRecorder {
    fn call(&self, work: RecordWork) -> LocalBoxFuture<'_, Result<String, String>> {
        Box::pin(async move {
            let op = work.op();
            if let RecordWork::Start { task } = &work {
                self.set_task(task).await?;
            }
            let service = self.service(op)?;
            log::debug!("record: calling {} ({})", service.name(), self.node);
            service.call(timeout(op)).await
        })
    }
}
