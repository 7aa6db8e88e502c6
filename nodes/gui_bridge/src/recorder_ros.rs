//! The Record card's ROS side ([`crate::RecorderControl`]): the recorder node's `task`
//! parameter set through its parameter services, and its episode services
//! (`recorder/start_episode`, `save_episode`, `discard_episode`, std_srvs Trigger, in the
//! recorder node's namespace) called through [`EpisodeClient`], for the node the
//! `recorder_node` parameter names. The clients are made when the panel starts, so that
//! they are matched long before a button is pressed (the panel never waits for a match
//! with the node borrowed: the Foxglove server borrows it too; a request sent before a
//! match is lost, and ends as a call without an answer). Every call is bounded in time.

use crate::recording::{RecordOp, RecordWork};
use crate::RecorderControl;
use futures::future::LocalBoxFuture;
use ros_plumbing::episodes::{EpisodeCall, EpisodeClient};
use ros_plumbing::remote_params::RemoteParameters;
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

/// The service of `op`.
pub fn call_of(op: RecordOp) -> EpisodeCall {
    match op {
        RecordOp::Start => EpisodeCall::Start,
        RecordOp::Save => EpisodeCall::Save,
        RecordOp::Discard => EpisodeCall::Discard,
    }
}

/// The clients of one recorder node.
pub struct RosRecorder {
    params: Result<RemoteParameters, String>,
    episodes: Result<EpisodeClient, String>,
}

impl RosRecorder {
    /// The clients of the recorder node named `recorder` (in our namespace, or
    /// absolute); one that cannot be made is logged, and its calls fail saying why.
    pub fn new(ros: &mut RosNode, recorder: &str) -> RosRecorder {
        let params = RemoteParameters::new(ros, recorder)
            .map_err(|e| format!("no parameter client for {recorder}: {e}"));
        let episodes = EpisodeClient::new(ros, recorder)
            .map_err(|e| format!("no client of {recorder}'s episode services: {e}"));
        for e in [params.as_ref().err(), episodes.as_ref().err()]
            .into_iter()
            .flatten()
        {
            log::warn!("record: {e}");
        }
        RosRecorder { params, episodes }
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
            let episodes = self.episodes.as_ref().map_err(Clone::clone)?;
            let op = work.op();
            if let RecordWork::Start { task } = &work {
                self.set_task(task).await?;
            }
            let answer = episodes.call(call_of(op), timeout(op)).await?;
            if answer.success {
                Ok(answer.message)
            } else {
                Err(answer.message)
            }
        })
    }
}
