//! The ROS 2 command line: `--ros-args -r __ns:=/x -r __node:=n -r from:=to -p name:=value
//! --params-file f.yaml --log-level debug --`.
//!
//! ros2-client has no parser for it; this one follows rcl's grammar for the parts a
//! node needs, and refuses everything else with a message naming the argument.

use crate::error::PlumbingError;
use crate::value::yaml_to_parameter;
use ros2_client::ParameterValue;
use std::path::PathBuf;

/// One `-r [node:]from:=to` rule.
#[derive(Clone, Debug, PartialEq)]
pub struct Remap {
    /// Only for this node name (`node:from:=to`), or for every node.
    pub node: Option<String>,
    /// Name to replace (relative names are expanded in the node's namespace).
    pub from: String,
    /// Replacement.
    pub to: String,
}

/// One `-p [node:]name:=value` override.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamOverride {
    /// Only for this node name, or for every node.
    pub node: Option<String>,
    /// Parameter name.
    pub name: String,
    /// Value, typed as YAML would type it.
    pub value: ParameterValue,
}

/// Everything found between `--ros-args` and `--` (or the end).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RosArgs {
    /// `-r __ns:=/x`
    pub namespace: Option<String>,
    /// `-r __node:=name` (or `__name`)
    pub node_name: Option<String>,
    /// Topic and service remaps, in order.
    pub remaps: Vec<Remap>,
    /// `-p` overrides, in order.
    pub params: Vec<ParamOverride>,
    /// `--params-file` paths, in order.
    pub params_files: Vec<PathBuf>,
    /// `--log-level LEVEL`
    pub log_level: Option<log::LevelFilter>,
    /// `--disable-rosout-logs` sets this to false.
    pub rosout_logs: Option<bool>,
    /// `--disable-stdout-logs` sets this to false (our logs go to stderr, as rcutils' do).
    pub stdout_logs: Option<bool>,
    /// `--enclave /NAME` (or `-e /NAME`): the SROS2 enclave, a directory under the
    /// keystore's `enclaves/` ([`crate::security`]).
    pub enclave: Option<String>,
}

/// Split a program's arguments (without argv\[0\]) into the program's own and the ROS ones.
///
/// # Examples
/// ```
/// use ros_plumbing::args::parse;
/// let argv = ["--once", "--ros-args", "-r", "__ns:=/arm2", "-p", "rate:=50", "--", "0.2"];
/// let (user, ros) = parse(argv.iter().map(|s| s.to_string())).unwrap();
/// assert_eq!(user, ["--once", "0.2"]);
/// assert_eq!(ros.namespace.as_deref(), Some("/arm2"));
/// assert_eq!(ros.params[0].value, ros2_client::ParameterValue::Integer(50));
/// ```
pub fn parse(
    argv: impl IntoIterator<Item = String>,
) -> Result<(Vec<String>, RosArgs), PlumbingError> {
    let mut user = Vec::new();
    let mut ros = RosArgs::default();
    let mut it = argv.into_iter();
    let mut in_ros = false;
    while let Some(arg) = it.next() {
        if !in_ros {
            if arg == "--ros-args" {
                in_ros = true;
            } else {
                user.push(arg);
            }
            continue;
        }
        let mut value_of = |flag: &str| {
            it.next().ok_or_else(|| PlumbingError::BadArgument {
                arg: flag.to_string(),
                why: "needs a value after it".into(),
            })
        };
        match arg.as_str() {
            "--" => in_ros = false,
            "--ros-args" => {}
            "-r" | "--remap" => {
                let rule = value_of(&arg)?;
                parse_remap(&rule, &mut ros)?;
            }
            "-p" | "--param" => {
                let rule = value_of(&arg)?;
                ros.params.push(parse_param(&rule)?);
            }
            "--params-file" => ros.params_files.push(PathBuf::from(value_of(&arg)?)),
            "--log-level" => {
                let level = value_of(&arg)?;
                // `--log-level name:=level` sets one logger; we have one per node.
                let level = level.rsplit(":=").next().unwrap_or(&level).to_string();
                ros.log_level = Some(parse_level(&level)?);
            }
            "--enable-rosout-logs" => ros.rosout_logs = Some(true),
            "--disable-rosout-logs" => ros.rosout_logs = Some(false),
            "--enable-stdout-logs" => ros.stdout_logs = Some(true),
            "--disable-stdout-logs" => ros.stdout_logs = Some(false),
            "--enable-external-lib-logs" | "--disable-external-lib-logs" => {}
            "-e" | "--enclave" => ros.enclave = Some(value_of(&arg)?),
            other => {
                return Err(PlumbingError::BadArgument {
                    arg: other.to_string(),
                    why: "unknown ROS argument (supported: -r/--remap, -p/--param, --params-file, --log-level, \
                          --enable/--disable-rosout-logs, --enable/--disable-stdout-logs, -e/--enclave)"
                        .into(),
                })
            }
        }
    }
    Ok((user, ros))
}

fn split_rule<'a>(
    rule: &'a str,
    what: &str,
) -> Result<(Option<&'a str>, &'a str, &'a str), PlumbingError> {
    let (lhs, rhs) = rule
        .split_once(":=")
        .ok_or_else(|| PlumbingError::BadArgument {
            arg: rule.to_string(),
            why: format!("a {what} needs the form name:=value"),
        })?;
    // `node:name:=value` applies to one node only.
    let (node, name) = match lhs.split_once(':') {
        Some((node, name)) => (Some(node), name),
        None => (None, lhs),
    };
    if name.is_empty() {
        return Err(PlumbingError::BadArgument {
            arg: rule.to_string(),
            why: format!("the {what} has an empty name"),
        });
    }
    Ok((node, name, rhs))
}

fn parse_remap(rule: &str, ros: &mut RosArgs) -> Result<(), PlumbingError> {
    let (node, from, to) = split_rule(rule, "remap rule")?;
    if to.is_empty() {
        return Err(PlumbingError::BadArgument {
            arg: rule.to_string(),
            why: "the remap rule has an empty replacement".into(),
        });
    }
    // Node-specific __ns/__node rules are honoured only for the matching node: keep
    // them as remaps and let the node apply them.
    match (node, from) {
        (None, "__ns") => ros.namespace = Some(to.to_string()),
        (None, "__node" | "__name") => ros.node_name = Some(to.to_string()),
        _ => ros.remaps.push(Remap {
            node: node.map(str::to_string),
            from: from.to_string(),
            to: to.to_string(),
        }),
    }
    Ok(())
}

fn parse_param(rule: &str) -> Result<ParamOverride, PlumbingError> {
    let (node, name, value) = split_rule(rule, "parameter")?;
    let yaml: serde_norway::Value = if value.is_empty() {
        serde_norway::Value::String(String::new())
    } else {
        serde_norway::from_str(value).map_err(|e| PlumbingError::BadArgument {
            arg: rule.to_string(),
            why: format!("value is not valid YAML: {e}"),
        })?
    };
    let value = yaml_to_parameter(&yaml).map_err(|why| PlumbingError::BadArgument {
        arg: rule.to_string(),
        why,
    })?;
    Ok(ParamOverride {
        node: node.map(str::to_string),
        name: name.to_string(),
        value,
    })
}

fn parse_level(level: &str) -> Result<log::LevelFilter, PlumbingError> {
    Ok(match level.to_ascii_lowercase().as_str() {
        "debug" => log::LevelFilter::Debug,
        "info" => log::LevelFilter::Info,
        "warn" | "warning" => log::LevelFilter::Warn,
        "error" | "fatal" => log::LevelFilter::Error,
        "trace" => log::LevelFilter::Trace,
        "off" | "unset" => log::LevelFilter::Off,
        _ => {
            return Err(PlumbingError::BadArgument {
                arg: level.to_string(),
                why: "log level must be one of debug, info, warn, error, fatal".into(),
            })
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(v: &[&str]) -> Result<(Vec<String>, RosArgs), PlumbingError> {
        parse(v.iter().map(|s| s.to_string()))
    }

    #[test]
    fn full_command_line() {
        let (user, ros) = p(&[
            "x",
            "--ros-args",
            "-r",
            "__ns:=/arm2",
            "-r",
            "__node:=ik2",
            "-r",
            "xyz_target:=/goal",
            "-r",
            "compute_ik:servo_angles:=angles",
            "-p",
            "rate:=50.5",
            "--param",
            "name:=hello",
            "--params-file",
            "/tmp/p.yaml",
            "--log-level",
            "debug",
            "--",
            "y",
        ])
        .unwrap();
        assert_eq!(user, ["x", "y"]);
        assert_eq!(ros.namespace.as_deref(), Some("/arm2"));
        assert_eq!(ros.node_name.as_deref(), Some("ik2"));
        assert_eq!(
            ros.remaps[0],
            Remap {
                node: None,
                from: "xyz_target".into(),
                to: "/goal".into()
            }
        );
        assert_eq!(ros.remaps[1].node.as_deref(), Some("compute_ik"));
        assert_eq!(ros.params[0].value, ParameterValue::Double(50.5));
        assert_eq!(ros.params[1].value, ParameterValue::String("hello".into()));
        assert_eq!(ros.params_files, [PathBuf::from("/tmp/p.yaml")]);
        assert_eq!(ros.log_level, Some(log::LevelFilter::Debug));
    }

    #[test]
    fn yaml_typed_values() {
        let (_, ros) = p(&[
            "--ros-args",
            "-p",
            "a:=true",
            "-p",
            "b:=3",
            "-p",
            "c:=[1.0, 2]",
            "-p",
            "d:=/dev/ttyACM0",
            "-p",
            "e:=",
        ])
        .unwrap();
        let v: Vec<_> = ros.params.iter().map(|p| p.value.clone()).collect();
        assert_eq!(
            v,
            [
                ParameterValue::Boolean(true),
                ParameterValue::Integer(3),
                ParameterValue::DoubleArray(vec![1.0, 2.0]),
                ParameterValue::String("/dev/ttyACM0".into()),
                ParameterValue::String(String::new()),
            ]
        );
    }

    #[test]
    fn malformed_arguments_are_named() {
        for (argv, needle) in [
            (&["--ros-args", "-r"][..], "-r"),
            (&["--ros-args", "-r", "foo"][..], "foo"),
            (&["--ros-args", "-p", ":=3"][..], ":=3"),
            (&["--ros-args", "--bogus"][..], "--bogus"),
            (&["--ros-args", "--log-level", "loud"][..], "loud"),
            (
                &["--ros-args", "-p", "a:=[1, {b: 2}]"][..],
                "a:=[1, {b: 2}]",
            ),
        ] {
            let err = p(argv).unwrap_err().to_string();
            assert!(err.contains(needle), "{argv:?}: {err}");
        }
    }

    #[test]
    fn several_ros_args_blocks() {
        let (user, ros) = p(&[
            "--ros-args",
            "-p",
            "a:=1",
            "--",
            "u",
            "--ros-args",
            "-p",
            "b:=2",
        ])
        .unwrap();
        assert_eq!(user, ["u"]);
        assert_eq!(ros.params.len(), 2);
    }
}
