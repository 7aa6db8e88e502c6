//! A client of a `recorder`'s episode services (`recorder/start_episode`,
//! `recorder/save_episode`, `recorder/discard_episode`, std_srvs/srv/Trigger) and of its
//! `task` parameter: the recorder's command line and the panel's Record button.

use crate::remote_params::RemoteParameters;
use crate::service::{client, namespace_of};
use crate::topics::{self, Callable};
use crate::{PlumbingError, RosNode};
use eezybot_msgs::std_srvs::{TriggerRequest, TriggerResponse};
use ros2_client::{Client, ParameterValue};
use std::time::Duration;

/// An episode request.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EpisodeCall {
    /// Begin an episode of the recorder's `task`.
    Start,
    /// End it and keep it.
    Save,
    /// End it and throw it away.
    Discard,
}

impl EpisodeCall {
    /// The service of the contract.
    pub fn callable(self) -> &'static Callable {
        match self {
            EpisodeCall::Start => &topics::START_EPISODE,
            EpisodeCall::Save => &topics::SAVE_EPISODE,
            EpisodeCall::Discard => &topics::DISCARD_EPISODE,
        }
    }
}

/// A client of one recorder.
pub struct EpisodeClient {
    node_name: String,
    start: Client<TriggerRequest, TriggerResponse>,
    save: Client<TriggerRequest, TriggerResponse>,
    discard: Client<TriggerRequest, TriggerResponse>,
    params: RemoteParameters,
}

impl EpisodeClient {
    /// The recorder named `node` (in our namespace, or absolute): its services are
    /// `recorder/...` in its namespace, as `ros2 service call` names them.
    pub fn new(ros: &mut RosNode, node: &str) -> Result<Self, PlumbingError> {
        let node_name = ros.resolver().resolve(node)?;
        let namespace = namespace_of(&node_name).to_string();
        let mut trigger = |c: &Callable| {
            client(
                ros,
                &format!("{namespace}/{}", c.name),
                c.package,
                c.type_name,
            )
        };
        Ok(EpisodeClient {
            start: trigger(&topics::START_EPISODE)?,
            save: trigger(&topics::SAVE_EPISODE)?,
            discard: trigger(&topics::DISCARD_EPISODE)?,
            params: RemoteParameters::new(ros, node)?,
            node_name,
        })
    }

    /// The recorder's full name.
    pub fn node_name(&self) -> &str {
        &self.node_name
    }

    fn of(&self, call: EpisodeCall) -> &Client<TriggerRequest, TriggerResponse> {
        match call {
            EpisodeCall::Start => &self.start,
            EpisodeCall::Save => &self.save,
            EpisodeCall::Discard => &self.discard,
        }
    }

    /// Wait until `call`'s service answers, at most `timeout`.
    pub async fn wait(
        &self,
        ros: &RosNode,
        call: EpisodeCall,
        timeout: Duration,
    ) -> Result<(), String> {
        tokio::time::timeout(timeout, self.of(call).wait_for_service(ros.node()))
            .await
            .map_err(|_| {
                format!(
                    "{} has no {} within {:.0} s (is the recorder running in this ROS domain?)",
                    self.node_name,
                    call.callable().name,
                    timeout.as_secs_f64()
                )
            })
    }

    /// Set the task of the episodes started from now on (the recorder's `task`).
    pub async fn set_task(
        &self,
        ros: &RosNode,
        task: &str,
        timeout: Duration,
    ) -> Result<(), String> {
        self.params
            .wait(ros, timeout)
            .await
            .map_err(|e| e.to_string())?;
        tokio::time::timeout(
            timeout,
            self.params
                .set("task", ParameterValue::String(task.to_string())),
        )
        .await
        .map_err(|_| {
            format!(
                "{} did not take the task within {timeout:?}",
                self.node_name
            )
        })?
    }

    /// Make `call`: the recorder's answer (done or not, and its message), or why there
    /// was none within `timeout`.
    pub async fn call(
        &self,
        call: EpisodeCall,
        timeout: Duration,
    ) -> Result<TriggerResponse, String> {
        tokio::time::timeout(
            timeout,
            self.of(call).async_call_service(TriggerRequest::default()),
        )
        .await
        .map_err(|_| {
            format!(
                "{} did not answer {} within {:.0} s",
                self.node_name,
                call.callable().name,
                timeout.as_secs_f64()
            )
        })?
        .map_err(|e| format!("{}: {e:?}", call.callable().name))
    }
}
