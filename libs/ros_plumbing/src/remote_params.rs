//! Another node's parameters, through its `get_parameters` / `set_parameters`
//! services (rcl_interfaces), as `ros2 param get/set` reaches them: for a tool that
//! switches a running node's mode, e.g. `gui_bridge --play --line` setting compute_ik's
//! `motion` for the playback and putting it back afterwards.
//!
//! Every remote parameter get and set of ours goes through [`RemoteParameters`]: typed
//! ([`RemoteParameters::get_as`], [`RemoteParameters::set_as`]) or as a
//! [`ParameterValue`] ([`RemoteParameters::get_value`], [`RemoteParameters::set_value`]),
//! each failure a [`RemoteParamError`].

use crate::service::client;
use crate::{PlumbingError, RosNode};
use ros2_client::rcl_interfaces::{
    GetParametersRequest, GetParametersResponse, SetParametersRequest, SetParametersResponse,
};
use ros2_client::{parameters::raw, Client, ParameterValue};
use std::time::Duration;

/// Why a remote parameter could not be read or set.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum RemoteParamError {
    /// The node's parameter services did not show up.
    #[error("{node} does not answer parameter requests within {:.0} s (is it running in this ROS domain?)", .timeout.as_secs_f64())]
    NotAnswering {
        /// the node's full name
        node: String,
        /// how long we waited
        timeout: Duration,
    },
    /// The request could not be sent or its reply not read.
    #[error("{node}/{service}: {why}")]
    Call {
        /// the node's full name
        node: String,
        /// `get_parameters` or `set_parameters`
        service: &'static str,
        /// what ros2-client said
        why: String,
    },
    /// The node has no such parameter.
    #[error("{node} has no `{name}` parameter")]
    Missing {
        /// the node's full name
        node: String,
        /// the parameter
        name: String,
    },
    /// The parameter's value is not of the type asked for.
    #[error("{node}'s `{name}` is {found:?}, not {want}")]
    WrongType {
        /// the node's full name
        node: String,
        /// the parameter
        name: String,
        /// the type asked for
        want: &'static str,
        /// what the node has
        found: ParameterValue,
    },
    /// The node refused the set, with its reason.
    #[error("{node} refused {name}: {reason}")]
    Refused {
        /// the node's full name
        node: String,
        /// the parameter
        name: String,
        /// the node's reason
        reason: String,
    },
    /// The node's reply had no result for the parameter.
    #[error("{node} answered nothing for {name}")]
    NoResult {
        /// the node's full name
        node: String,
        /// the parameter
        name: String,
    },
}

pub use crate::value::ParamType;

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
        let get = client(
            ros,
            &format!("{node_name}/get_parameters"),
            "rcl_interfaces",
            "GetParameters",
        )?;
        let set = client(
            ros,
            &format!("{node_name}/set_parameters"),
            "rcl_interfaces",
            "SetParameters",
        )?;
        Ok(Self {
            node_name,
            get,
            set,
        })
    }

    /// A call of `service` that failed.
    fn call_error(&self, service: &'static str, e: impl std::fmt::Debug) -> RemoteParamError {
        RemoteParamError::Call {
            node: self.node_name.clone(),
            service,
            why: format!("{e:?}"),
        }
    }

    /// The node's full name.
    pub fn node_name(&self) -> &str {
        &self.node_name
    }

    /// Wait until the node's parameter services answer, at most `timeout`.
    pub async fn wait(&self, ros: &RosNode, timeout: Duration) -> Result<(), RemoteParamError> {
        let ready = async {
            self.get.wait_for_service(ros.node()).await;
            self.set.wait_for_service(ros.node()).await;
        };
        tokio::time::timeout(timeout, ready)
            .await
            .map_err(|_| RemoteParamError::NotAnswering {
                node: self.node_name.clone(),
                timeout,
            })
    }

    /// One parameter's value (`None`: the node does not have it).
    pub async fn get_value(&self, name: &str) -> Result<Option<ParameterValue>, RemoteParamError> {
        let resp = self
            .get
            .async_call_service(GetParametersRequest {
                names: vec![name.to_string()],
            })
            .await
            .map_err(|e| self.call_error("get_parameters", e))?;
        Ok(present(
            resp.values.into_iter().next().map(ParameterValue::from),
        ))
    }

    /// One parameter's value as `T`; a parameter the node does not have, or of
    /// another type, is an error.
    pub async fn get_as<T: ParamType>(&self, name: &str) -> Result<T, RemoteParamError> {
        let value = self
            .get_value(name)
            .await?
            .ok_or_else(|| RemoteParamError::Missing {
                node: self.node_name.clone(),
                name: name.to_string(),
            })?;
        T::from_value(value).map_err(|found| RemoteParamError::WrongType {
            node: self.node_name.clone(),
            name: name.to_string(),
            want: T::NAME,
            found,
        })
    }

    /// Set one parameter; the node's refusal comes back as
    /// [`RemoteParamError::Refused`], with its reason.
    pub async fn set_value(
        &self,
        name: &str,
        value: ParameterValue,
    ) -> Result<(), RemoteParamError> {
        let resp = self
            .set
            .async_call_service(SetParametersRequest {
                parameter: vec![raw::Parameter {
                    name: name.to_string(),
                    value: value.into(),
                }],
            })
            .await
            .map_err(|e| self.call_error("set_parameters", e))?;
        set_outcome(&self.node_name, name, resp.results.into_iter().next())
    }

    /// Set one parameter to a `T`.
    pub async fn set_as<T: ParamType>(&self, name: &str, value: T) -> Result<(), RemoteParamError> {
        self.set_value(name, value.into_value()).await
    }

    /// [`Self::get_value`] with the error as text, for the callers written before
    /// [`RemoteParamError`] (gui_bridge's; to go once they use the typed calls).
    pub async fn get(&self, name: &str) -> Result<Option<ParameterValue>, String> {
        self.get_value(name).await.map_err(|e| e.to_string())
    }

    /// [`Self::set_value`] with the error as text, for the callers written before
    /// [`RemoteParamError`] (gui_bridge's; to go once they use the typed calls).
    pub async fn set(&self, name: &str, value: ParameterValue) -> Result<(), String> {
        self.set_value(name, value).await.map_err(|e| e.to_string())
    }
}

/// A get's value, `None` when the node does not have the parameter (`NotSet`).
fn present(value: Option<ParameterValue>) -> Option<ParameterValue> {
    value.filter(|v| !matches!(v, ParameterValue::NotSet))
}

/// A set's reply for one parameter.
fn set_outcome(
    node: &str,
    name: &str,
    result: Option<raw::SetParametersResult>,
) -> Result<(), RemoteParamError> {
    match result {
        Some(r) if r.successful => Ok(()),
        Some(r) => Err(RemoteParamError::Refused {
            node: node.to_string(),
            name: name.to_string(),
            reason: r.reason,
        }),
        None => Err(RemoteParamError::NoResult {
            node: node.to_string(),
            name: name.to_string(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use raw::SetParametersResult;

    #[test]
    fn a_set_is_ok_refused_with_the_reason_or_unanswered() {
        let ok = SetParametersResult {
            successful: true,
            reason: String::new(),
        };
        assert_eq!(set_outcome("/compute_ik", "motion", Some(ok)), Ok(()));
        let no = SetParametersResult {
            successful: false,
            reason: "motion must be one of joint, line".into(),
        };
        let refused = set_outcome("/compute_ik", "motion", Some(no)).unwrap_err();
        assert_eq!(
            refused.to_string(),
            "/compute_ik refused motion: motion must be one of joint, line"
        );
        assert!(matches!(
            set_outcome("/compute_ik", "motion", None),
            Err(RemoteParamError::NoResult { .. })
        ));
    }

    #[test]
    fn a_missing_parameter_is_none() {
        assert_eq!(present(Some(ParameterValue::NotSet)), None);
        assert_eq!(present(None), None);
        assert_eq!(
            present(Some(ParameterValue::Integer(3))),
            Some(ParameterValue::Integer(3))
        );
    }

    #[test]
    fn values_convert_to_their_own_type_only() {
        assert_eq!(
            String::from_value("line".to_string().into_value()),
            Ok("line".to_string())
        );
        assert_eq!(bool::from_value(ParameterValue::Boolean(true)), Ok(true));
        assert_eq!(i64::from_value(ParameterValue::Integer(-2)), Ok(-2));
        assert_eq!(f64::from_value(ParameterValue::Double(0.5)), Ok(0.5));
        assert_eq!(
            f64::from_value(ParameterValue::Integer(1)),
            Err(ParameterValue::Integer(1))
        );
        assert_eq!(
            String::from_value(ParameterValue::Boolean(false)),
            Err(ParameterValue::Boolean(false))
        );
    }
}
