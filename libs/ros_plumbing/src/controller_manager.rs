//! A client of ros2_control's controller manager services, as `ros2 control` reaches
//! them: `controller_manager/list_controllers` and `controller_manager/switch_controller`
//! in the namespace of the node that serves them (compute_ik). gui_bridge's calibration
//! wizard takes the arm through it (activating `calibration`) and gives it back.
//!
//! A `calibration` activated by a switch is owned by its caller's participant, and given
//! back when the caller is silent for compute_ik's `calibration_lease`: a holder renews it
//! by listing the controllers ([`ControllerManager::list`]) more often than that.

use crate::service::{client, namespace_of};
use crate::topics::{LIST_CONTROLLERS, SWITCH_CONTROLLER};
use crate::{PlumbingError, RosNode};
use eezybot_msgs::builtin_interfaces::Duration as RosDuration;
use eezybot_msgs::controller_manager_msgs::{
    ControllerState, ListControllersRequest, ListControllersResponse, SwitchControllerRequest,
    SwitchControllerResponse,
};
use ros2_client::Client;
use std::time::Duration;

/// A client of one controller manager.
pub struct ControllerManager {
    namespace: String,
    list: Client<ListControllersRequest, ListControllersResponse>,
    switch: Client<SwitchControllerRequest, SwitchControllerResponse>,
}

impl ControllerManager {
    /// The controller manager beside `node` (a name in our namespace, or absolute): the
    /// services `controller_manager/...` in `node`'s namespace.
    pub fn new(ros: &mut RosNode, node: &str) -> Result<Self, PlumbingError> {
        let full = ros.resolver().resolve(node)?;
        let namespace = namespace_of(&full).to_string();
        let [list, switch] =
            [&LIST_CONTROLLERS, &SWITCH_CONTROLLER].map(|c| format!("{namespace}/{}", c.name));
        let list = client(
            ros,
            &list,
            LIST_CONTROLLERS.package,
            LIST_CONTROLLERS.type_name,
        )?;
        let switch = client(
            ros,
            &switch,
            SWITCH_CONTROLLER.package,
            SWITCH_CONTROLLER.type_name,
        )?;
        Ok(ControllerManager {
            namespace,
            list,
            switch,
        })
    }

    /// Where its services are: `/arm2/controller_manager`.
    pub fn name(&self) -> String {
        format!("{}/controller_manager", self.namespace)
    }

    /// Wait until both services answer, at most `timeout`.
    pub async fn wait(&self, ros: &RosNode, timeout: Duration) -> Result<(), String> {
        let ready = async {
            self.list.wait_for_service(ros.node()).await;
            self.switch.wait_for_service(ros.node()).await;
        };
        tokio::time::timeout(timeout, ready).await.map_err(|_| {
            format!(
                "{} does not answer within {:.0} s (is compute_ik running in this ROS domain?)",
                self.name(),
                timeout.as_secs_f64()
            )
        })
    }

    /// Every controller and its state (and, for a caller that holds `calibration`, its
    /// lease renewed).
    pub async fn list(&self) -> Result<Vec<ControllerState>, String> {
        self.list
            .async_call_service(ListControllersRequest::default())
            .await
            .map(|r| r.controller)
            .map_err(|e| format!("{}/list_controllers: {e:?}", self.name()))
    }

    /// The controllers active now.
    pub async fn active(&self) -> Result<Vec<String>, String> {
        Ok(self
            .list()
            .await?
            .into_iter()
            .filter(|c| c.state == "active")
            .map(|c| c.name)
            .collect())
    }

    /// A STRICT switch (all or nothing): `Ok` when done, else the manager's reason.
    pub async fn switch(&self, activate: &[&str], deactivate: &[&str]) -> Result<(), String> {
        let names = |n: &[&str]| n.iter().map(|s| s.to_string()).collect();
        let answer = self
            .switch
            .async_call_service(SwitchControllerRequest {
                activate_controllers: names(activate),
                deactivate_controllers: names(deactivate),
                strictness: SwitchControllerRequest::STRICT,
                activate_asap: true,
                timeout: RosDuration::default(),
            })
            .await
            .map_err(|e| format!("{}/switch_controller: {e:?}", self.name()))?;
        if answer.ok {
            Ok(())
        } else {
            Err(answer.message)
        }
    }
}
