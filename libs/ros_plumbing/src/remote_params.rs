//! Another node's parameters, through its `get_parameters` / `set_parameters`
//! services (rcl_interfaces), as `ros2 param get/set` reaches them: for a tool that
//! switches a running node's mode, e.g. `gui_bridge --play --line` setting compute_ik's
//! `motion` for the playback and putting it back afterwards.

use crate::{PlumbingError, RosNode};
use ros2_client::rcl_interfaces::{
    GetParametersRequest, GetParametersResponse, SetParametersRequest, SetParametersResponse,
};
use ros2_client::{parameters::raw, Client, Name, ParameterValue, ServiceMapping, ServiceTypeName};
use std::time::Duration;

/// A client of one node's parameter services.
pub struct RemoteParameters {
    node_name: String,
    get: Client<GetParametersRequest, GetParametersResponse>,
    set: Client<SetParametersRequest, SetParametersResponse>,
}

impl RemoteParameters {
    /// The parameters of `node` (a name in our namespace, or absolute).
    pub fn new(ros: &mut RosNode, node: &str) -> Result<Self, PlumbingError> {
        let node_name = ros.resolver().resolve(node)?;
        let service = |what: &str| {
            Name::parse(&format!("{node_name}/{what}")).map_err(|e| PlumbingError::Name {
                name: format!("{node_name}/{what}"),
                why: format!("{e:?}"),
            })
        };
        let qos = crate::qos::SERVICES;
        let get = ros
            .node_mut()
            .create_client(
                ServiceMapping::Enhanced,
                &service("get_parameters")?,
                &ServiceTypeName::new("rcl_interfaces", "GetParameters"),
                qos.clone(),
                qos.clone(),
            )
            .map_err(|e| PlumbingError::Ros(format!("{node_name}/get_parameters: {e:?}")))?;
        let set = ros
            .node_mut()
            .create_client(
                ServiceMapping::Enhanced,
                &service("set_parameters")?,
                &ServiceTypeName::new("rcl_interfaces", "SetParameters"),
                qos.clone(),
                qos,
            )
            .map_err(|e| PlumbingError::Ros(format!("{node_name}/set_parameters: {e:?}")))?;
        Ok(Self {
            node_name,
            get,
            set,
        })
    }

    /// The node's full name.
    pub fn node_name(&self) -> &str {
        &self.node_name
    }

    /// Wait until the node's parameter services answer, at most `timeout`.
    pub async fn wait(&self, ros: &RosNode, timeout: Duration) -> Result<(), String> {
        let ready = async {
            self.get.wait_for_service(ros.node()).await;
            self.set.wait_for_service(ros.node()).await;
        };
        tokio::time::timeout(timeout, ready).await.map_err(|_| {
            format!(
                "{} does not answer parameter requests within {:.0} s (is it running in this ROS domain?)",
                self.node_name,
                timeout.as_secs_f64()
            )
        })
    }

    /// One parameter's value (`None`: the node does not have it).
    pub async fn get(&self, name: &str) -> Result<Option<ParameterValue>, String> {
        let resp = self
            .get
            .async_call_service(GetParametersRequest {
                names: vec![name.to_string()],
            })
            .await
            .map_err(|e| format!("{}/get_parameters: {e:?}", self.node_name))?;
        Ok(resp
            .values
            .into_iter()
            .next()
            .map(ParameterValue::from)
            .filter(|v| !matches!(v, ParameterValue::NotSet)))
    }

    /// Set one parameter; the node's refusal comes back as the error, with its reason.
    pub async fn set(&self, name: &str, value: ParameterValue) -> Result<(), String> {
        let resp = self
            .set
            .async_call_service(SetParametersRequest {
                parameter: vec![raw::Parameter {
                    name: name.to_string(),
                    value: value.into(),
                }],
            })
            .await
            .map_err(|e| format!("{}/set_parameters: {e:?}", self.node_name))?;
        match resp.results.into_iter().next() {
            Some(r) if r.successful => Ok(()),
            Some(r) => Err(format!("{} refused {name}: {}", self.node_name, r.reason)),
            None => Err(format!("{} answered nothing for {name}", self.node_name)),
        }
    }
}
