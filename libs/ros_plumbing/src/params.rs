//! Declared parameters: defaults, types and ranges, overrides from `-p` and
//! `--params-file`, and a shared store that the parameter services update.

use crate::args::RosArgs;
use crate::error::PlumbingError;
use crate::logging::shorten;
use crate::value::{yaml_to_parameter, ParamType};
use eezybot_msgs::diagnostic_msgs::{DiagnosticStatus, KeyValue};
use ros2_client::{NumericRange, ParameterDescriptor, ParameterValue};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::{Arc, RwLock};

/// What values a parameter accepts beyond its type.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamRange {
    /// Any value of the type.
    Any,
    /// An integer in `min..=max`.
    Integer {
        /// lowest accepted
        min: i64,
        /// highest accepted
        max: i64,
    },
    /// A double in `min..=max` (finite).
    Double {
        /// lowest accepted
        min: f64,
        /// highest accepted
        max: f64,
    },
}

/// A further check of a parameter value; the error says why it is refused.
pub type ValueCheck = fn(&ParameterValue) -> Result<(), String>;

/// A further check of a string parameter's value; the error says why it is refused.
pub type TextCheck = fn(&str) -> Result<(), String>;

/// What a file parameter's [`FileLoader`] made of its file ([`Params::loaded`]).
pub type Loaded = Arc<dyn std::any::Any + Send + Sync>;

/// Loads the file a string parameter names ([`Params::load_with`]).
pub type FileLoader = fn(&str) -> Result<Loaded, String>;

/// A declared parameter.
#[derive(Clone, Debug)]
pub struct ParamSpec {
    /// Name, e.g. `publish_rate`.
    pub name: &'static str,
    /// Default value; its variant is the parameter's type.
    pub default: ParameterValue,
    /// What it does, for the README and `--help`.
    pub description: &'static str,
    /// Accepted range.
    pub range: ParamRange,
    /// If true, it can only be set at start (command line, params file).
    pub read_only: bool,
    /// What else a value must satisfy, in words (e.g. the accepted names); empty if
    /// nothing. `ros2 param describe` shows it as the additional constraints.
    pub constraints: &'static str,
    /// A further check of the value (e.g. that a file loads), after type and range.
    pub validator: Option<ValueCheck>,
    /// A further check of a string value ([`ParamSpec::text_check`]).
    pub text_check: Option<TextCheck>,
}

impl ParamSpec {
    /// A read-write parameter with no range.
    pub fn new(
        name: &'static str,
        default: ParameterValue,
        description: &'static str,
    ) -> ParamSpec {
        ParamSpec {
            name,
            default,
            description,
            range: ParamRange::Any,
            read_only: false,
            constraints: "",
            validator: None,
            text_check: None,
        }
    }

    /// A read-write string parameter naming a file to load, empty by default (empty:
    /// the shipped or built-in one); `constraints` says so in words, `check` loads it.
    pub fn file(
        name: &'static str,
        description: &'static str,
        constraints: &'static str,
        check: TextCheck,
    ) -> ParamSpec {
        ParamSpec::new(name, ParameterValue::String(String::new()), description)
            .constraints(constraints)
            .text_check(check)
    }

    /// With a range.
    pub fn range(mut self, range: ParamRange) -> ParamSpec {
        self.range = range;
        self
    }

    /// With a further check of the value.
    pub fn validator(mut self, check: ValueCheck) -> ParamSpec {
        self.validator = Some(check);
        self
    }

    /// With a further check of the value, a string (e.g. that the file it names loads):
    /// [`ParamSpec::validator`] for a string parameter.
    pub fn text_check(mut self, check: TextCheck) -> ParamSpec {
        self.text_check = Some(check);
        self
    }

    /// Settable only at start.
    pub fn read_only(mut self) -> ParamSpec {
        self.read_only = true;
        self
    }

    /// With further constraints described in words (see [`ParamSpec::constraints`]).
    pub fn constraints(mut self, constraints: &'static str) -> ParamSpec {
        self.constraints = constraints;
        self
    }

    /// The descriptor `describe_parameters` (`ros2 param describe`) answers with:
    /// description, read-only flag, range (step 0: any value in it) and constraints.
    pub fn descriptor(&self) -> ParameterDescriptor {
        ParameterDescriptor {
            name: self.name.to_string(),
            param_type: self.default.to_parameter_type(),
            description: self.description.to_string(),
            additional_constraints: self.constraints.to_string(),
            read_only: self.read_only,
            dynamic_typing: false,
            range: match self.range {
                ParamRange::Any => NumericRange::NotSpecified,
                ParamRange::Integer { min, max } => NumericRange::IntegerRange {
                    from_value: min,
                    to_value: max,
                    step: 0,
                },
                ParamRange::Double { min, max } => NumericRange::FloatingPointRange {
                    from_value: min,
                    to_value: max,
                    step: 0.0,
                },
            },
        }
    }

    /// Check a value against type and range; an integer is accepted for a double.
    pub fn check(&self, value: &ParameterValue) -> Result<ParameterValue, String> {
        let value = match (&self.default, value) {
            (ParameterValue::Double(_), ParameterValue::Integer(i)) => {
                ParameterValue::Double(*i as f64)
            }
            (ParameterValue::DoubleArray(_), ParameterValue::IntegerArray(v)) => {
                ParameterValue::DoubleArray(v.iter().map(|i| *i as f64).collect())
            }
            _ => value.clone(),
        };
        if std::mem::discriminant(&value) != std::mem::discriminant(&self.default) {
            return Err(format!(
                "expected {}, got {}",
                type_name(&self.default),
                type_name(&value)
            ));
        }
        match (&self.range, &value) {
            (ParamRange::Integer { min, max }, ParameterValue::Integer(v))
                if v < min || v > max =>
            {
                Err(format!("{v} is outside {min}..={max}"))
            }
            (ParamRange::Double { min, max }, ParameterValue::Double(v))
                if !(v >= min && v <= max) =>
            {
                Err(format!("{v} is outside {min}..={max}"))
            }
            _ => Ok(()),
        }?;
        if let Some(check) = self.validator {
            check(&value)?;
        }
        if let (Some(check), ParameterValue::String(text)) = (self.text_check, &value) {
            check(text)?;
        }
        Ok(value)
    }
}

fn type_name(v: &ParameterValue) -> &'static str {
    match v {
        ParameterValue::NotSet => "not set",
        ParameterValue::Boolean(_) => "a bool",
        ParameterValue::Integer(_) => "an integer",
        ParameterValue::Double(_) => "a double",
        ParameterValue::String(_) => "a string",
        ParameterValue::ByteArray(_) => "a byte array",
        ParameterValue::BooleanArray(_) => "a bool array",
        ParameterValue::IntegerArray(_) => "an integer array",
        ParameterValue::DoubleArray(_) => "a double array",
        ParameterValue::StringArray(_) => "a string array",
    }
}

/// Does a params-file node key (`/**`, `/arm2/compute_ik`, `compute_ik`, `/*/compute_ik`,
/// `/**/compute_ik`) select the node with fully qualified name `fqn`?
pub fn node_key_matches(key: &str, fqn: &str) -> bool {
    let key = if key.starts_with('/') {
        key.to_string()
    } else {
        format!("/{key}")
    };
    let pat: Vec<&str> = key.trim_start_matches('/').split('/').collect();
    let name: Vec<&str> = fqn.trim_start_matches('/').split('/').collect();
    fn m(p: &[&str], n: &[&str]) -> bool {
        match (p.first(), n.first()) {
            (None, None) => true,
            (Some(&"**"), _) => m(&p[1..], n) || (!n.is_empty() && m(p, &n[1..])),
            (Some(&"*"), Some(_)) => m(&p[1..], &n[1..]),
            (Some(a), Some(b)) if a == b => m(&p[1..], &n[1..]),
            _ => false,
        }
    }
    m(&pat, &name)
}

/// The `ros__parameters` for `fqn` from one params file, flattened to `a.b.c` names,
/// in file order (later keys win when applied in order).
pub fn read_params_file(
    path: &Path,
    fqn: &str,
) -> Result<Vec<(String, ParameterValue)>, PlumbingError> {
    let bad = |why: String| PlumbingError::ParamsFile {
        path: path.to_path_buf(),
        why,
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
    let doc: serde_norway::Value = serde_norway::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let serde_norway::Value::Mapping(nodes) = doc else {
        return Err(bad(
            "the top level must map node names to `ros__parameters:`".into(),
        ));
    };
    let mut out = Vec::new();
    for (key, body) in &nodes {
        let key = key
            .as_str()
            .ok_or_else(|| bad("node keys must be strings".into()))?;
        if !node_key_matches(key, fqn) {
            continue;
        }
        let params = body
            .get("ros__parameters")
            .ok_or_else(|| bad(format!("`{key}:` has no `ros__parameters:` section")))?;
        flatten("", params, &mut out).map_err(|e| bad(format!("under `{key}`: {e}")))?;
    }
    Ok(out)
}

fn flatten(
    prefix: &str,
    v: &serde_norway::Value,
    out: &mut Vec<(String, ParameterValue)>,
) -> Result<(), String> {
    match v {
        serde_norway::Value::Mapping(m) => {
            for (k, child) in m {
                let k = match k {
                    serde_norway::Value::String(s) => s.clone(),
                    other => serde_norway::to_string(other)
                        .unwrap_or_default()
                        .trim()
                        .to_string(),
                };
                let name = if prefix.is_empty() {
                    k
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&name, child, out)?;
            }
            Ok(())
        }
        other => {
            let value = yaml_to_parameter(other).map_err(|e| format!("`{prefix}`: {e}"))?;
            out.push((prefix.to_string(), value));
            Ok(())
        }
    }
}

/// The parameter every ROS 2 node has; ros2-client keeps it (it subscribes to `/clock`
/// while it is true), this spec describes and checks it.
pub static USE_SIM_TIME: std::sync::LazyLock<ParamSpec> = std::sync::LazyLock::new(|| {
    ParamSpec::new(
        "use_sim_time",
        ParameterValue::Boolean(false),
        "follow the simulated time on /clock (rosgraph_msgs/msg/Clock) instead of the \
         system clock; these nodes still stamp their own messages with the system clock",
    )
});

/// Starting values: defaults, then params files in order, then `-p` in order; each
/// checked against its spec. Unknown names are refused (a typo should not pass silently).
pub fn initial_values(
    specs: &[ParamSpec],
    args: &RosArgs,
    fqn: &str,
    node_name: &str,
) -> Result<BTreeMap<String, ParameterValue>, PlumbingError> {
    let mut values: BTreeMap<String, ParameterValue> = specs
        .iter()
        .map(|s| (s.name.to_string(), s.default.clone()))
        .collect();
    let mut overrides: Vec<(String, ParameterValue, String)> = Vec::new();
    for path in &args.params_files {
        for (name, value) in read_params_file(path, fqn)? {
            overrides.push((name, value, path.display().to_string()));
        }
    }
    for p in &args.params {
        if p.node.as_deref().is_none_or(|n| n == node_name) {
            overrides.push((p.name.clone(), p.value.clone(), "-p".into()));
        }
    }
    for (name, value, origin) in overrides {
        let spec = specs
            .iter()
            .chain([&*USE_SIM_TIME])
            .find(|s| s.name == name)
            .ok_or_else(|| PlumbingError::Parameter {
                name: name.clone(),
                why: format!(
                    "not a parameter of this node (from {origin}); known: {}",
                    specs.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
                ),
            })?;
        let value = spec.check(&value).map_err(|why| PlumbingError::Parameter {
            name: name.clone(),
            why: format!("{why} (from {origin})"),
        })?;
        values.insert(name, value);
    }
    Ok(values)
}

/// The node's current parameter values, shared with the parameter services.
/// Cloning gives another handle to the same values.
#[derive(Clone, Debug)]
pub struct Params {
    values: Arc<RwLock<BTreeMap<String, ParameterValue>>>,
    changed: Arc<tokio::sync::watch::Sender<u64>>,
    refusals: Arc<RwLock<Refusals>>,
    /// file parameters: their loader, and what it made of the file the value names
    files: Arc<RwLock<BTreeMap<String, (FileLoader, Loaded)>>>,
}

/// The values the parameter services refused: how many, and the last one.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Refusals {
    /// Refused values since the start.
    pub count: u64,
    /// The last one: the parameter's name and why (cut to [`REFUSAL_MAX`] characters).
    pub last: Option<(String, String)>,
}

/// The length a refusal's name and reason are cut to in [`Refusals`], logs and
/// diagnostics (the reply to the caller keeps the whole reason).
pub const REFUSAL_MAX: usize = 300;

impl Params {
    /// A store with these values.
    pub fn new(values: BTreeMap<String, ParameterValue>) -> Params {
        let (tx, _rx) = tokio::sync::watch::channel(0);
        Params {
            values: Arc::new(RwLock::new(values)),
            changed: Arc::new(tx),
            refusals: Arc::default(),
            files: Arc::default(),
        }
    }

    /// Load the file parameter `name`'s file with `loader` now, and again whenever the
    /// parameter is set, by whoever sets it (the parameter services, off the node's
    /// loop), before the change is announced: the loop reads the result with
    /// [`Params::loaded`] and never touches the file. Fails if the current file does not
    /// load.
    pub fn load_with(&self, name: &str, loader: FileLoader) -> Result<(), String> {
        let loaded = loader(&self.string(name).unwrap_or_default())?;
        if let Ok(mut f) = self.files.write() {
            f.insert(name.to_string(), (loader, loaded));
        }
        Ok(())
    }

    /// What the loader of file parameter `name` made of the file its value names, if
    /// it has a loader ([`Params::load_with`]) and made a `T`.
    pub fn loaded<T: std::any::Any + Send + Sync>(&self, name: &str) -> Option<Arc<T>> {
        let loaded = self.files.read().ok()?.get(name)?.1.clone();
        loaded.downcast::<T>().ok()
    }

    /// Record a value the parameter services refused (the value is not stored), log it
    /// and return the reason unchanged for the reply.
    pub fn note_refusal(&self, name: &str, reason: String) -> String {
        let name = shorten(name, crate::logging::NAME_MAX).into_owned();
        let short = shorten(&reason, REFUSAL_MAX).into_owned();
        log::warn!("parameter {name} refused, keeping its value: {short}");
        if let Ok(mut r) = self.refusals.write() {
            r.count += 1;
            r.last = Some((name, short));
        }
        reason
    }

    /// The values refused so far ([`Params::note_refusal`]).
    pub fn refusals(&self) -> Refusals {
        self.refusals.read().map(|r| r.clone()).unwrap_or_default()
    }

    /// Add `parameters_refused` and, after a refusal, `last_parameter_refusal` to a
    /// node's `diagnostics` entry.
    pub fn annotate(&self, status: &mut DiagnosticStatus) {
        let r = self.refusals();
        status.values.push(KeyValue {
            key: "parameters_refused".into(),
            value: r.count.to_string(),
        });
        if let Some((name, reason)) = r.last {
            status.values.push(KeyValue {
                key: "last_parameter_refusal".into(),
                value: format!("{name}: {reason}"),
            });
        }
    }

    /// Current value.
    pub fn get(&self, name: &str) -> Option<ParameterValue> {
        self.values.read().ok().and_then(|v| v.get(name).cloned())
    }

    /// Current value of a parameter of type `T`; `None` when it has another type.
    pub fn get_as<T: ParamType>(&self, name: &str) -> Option<T> {
        self.get(name).and_then(|v| T::from_value(v).ok())
    }

    /// Current value of a double parameter.
    pub fn f64(&self, name: &str) -> Option<f64> {
        self.get_as(name)
    }

    /// Current value of an integer parameter.
    pub fn i64(&self, name: &str) -> Option<i64> {
        self.get_as(name)
    }

    /// Current value of a string parameter.
    pub fn string(&self, name: &str) -> Option<String> {
        self.get_as(name)
    }

    /// Current value of a bool parameter.
    pub fn bool(&self, name: &str) -> Option<bool> {
        self.get_as(name)
    }

    /// Store a value (already checked) and wake [`Params::subscribe`]rs.
    pub fn set(&self, name: &str, value: ParameterValue) {
        if let (Ok(mut files), ParameterValue::String(path)) = (self.files.write(), &value) {
            if let Some((loader, loaded)) = files.get_mut(name) {
                // (checked by the parameter services before it was stored: a file that
                // changed since keeps what was loaded before)
                match loader(path) {
                    Ok(l) => *loaded = l,
                    Err(e) => log::error!("{name}: keeping the file loaded before: {e}"),
                }
            }
        }
        if let Ok(mut v) = self.values.write() {
            v.insert(name.to_string(), value);
        }
        self.changed.send_modify(|n| *n += 1);
    }

    /// A receiver that wakes when any parameter changes.
    pub fn subscribe(&self) -> tokio::sync::watch::Receiver<u64> {
        self.changed.subscribe()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::args::parse;

    #[test]
    fn node_keys() {
        assert!(node_key_matches("/**", "/compute_ik"));
        assert!(node_key_matches("/**", "/arm2/compute_ik"));
        assert!(node_key_matches("compute_ik", "/compute_ik"));
        assert!(!node_key_matches("compute_ik", "/arm2/compute_ik"));
        assert!(node_key_matches("/arm2/compute_ik", "/arm2/compute_ik"));
        assert!(node_key_matches("/**/compute_ik", "/a/b/compute_ik"));
        assert!(node_key_matches("/*/compute_ik", "/arm2/compute_ik"));
        assert!(!node_key_matches("/*/compute_ik", "/compute_ik"));
        assert!(!node_key_matches("/arm2/serial_node", "/arm2/compute_ik"));
    }

    fn specs() -> Vec<ParamSpec> {
        vec![
            ParamSpec::new("rate", ParameterValue::Double(10.0), "").range(ParamRange::Double {
                min: 1.0,
                max: 100.0,
            }),
            ParamSpec::new("port", ParameterValue::String("/dev/ttyACM0".into()), ""),
            ParamSpec::new("nested.gain", ParameterValue::Integer(1), "")
                .range(ParamRange::Integer { min: 0, max: 5 }),
        ]
    }

    #[test]
    fn file_then_command_line_and_ranges() {
        let dir = std::env::temp_dir().join(format!("plumbing-params-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("p.yaml");
        std::fs::write(
            &file,
            "/**:\n  ros__parameters:\n    rate: 20\n    nested:\n      gain: 3\n/other:\n  ros__parameters:\n    bogus: 1\ncompute_ik:\n  ros__parameters:\n    port: mock\n",
        )
        .unwrap();
        let argv = [
            "--ros-args",
            "--params-file",
            file.to_str().unwrap(),
            "-p",
            "rate:=30.5",
        ];
        let (_, args) = parse(argv.iter().map(|s| s.to_string())).unwrap();
        let v = initial_values(&specs(), &args, "/compute_ik", "compute_ik").unwrap();
        assert_eq!(v["rate"], ParameterValue::Double(30.5));
        assert_eq!(v["port"], ParameterValue::String("mock".into()));
        assert_eq!(v["nested.gain"], ParameterValue::Integer(3));

        for (bad, needle) in [
            ("rate:=500.0", "outside"),
            ("rate:=fast", "expected a double"),
            ("ratee:=1.0", "not a parameter"),
        ] {
            let argv = ["--ros-args", "-p", bad];
            let (_, args) = parse(argv.iter().map(|s| s.to_string())).unwrap();
            let err = initial_values(&specs(), &args, "/compute_ik", "compute_ik")
                .unwrap_err()
                .to_string();
            assert!(err.contains(needle), "{bad}: {err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_text_check_sees_string_values() {
        let spec =
            ParamSpec::new("mode", ParameterValue::String("a".into()), "").text_check(
                |s| match s {
                    "a" | "b" => Ok(()),
                    _ => Err("must be `a` or `b`".into()),
                },
            );
        assert!(spec.check(&ParameterValue::String("b".into())).is_ok());
        assert_eq!(
            spec.check(&ParameterValue::String("c".into())),
            Err("must be `a` or `b`".into())
        );
        assert_eq!(
            spec.check(&ParameterValue::Integer(1)),
            Err("expected a string, got an integer".into())
        );
    }

    #[test]
    fn malformed_params_file_names_file_and_problem() {
        let dir = std::env::temp_dir().join(format!("plumbing-badparams-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("bad.yaml");
        std::fs::write(&file, "/**:\n  parameters:\n    rate: 1\n").unwrap();
        let err = read_params_file(&file, "/compute_ik")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("bad.yaml") && err.contains("ros__parameters"),
            "{err}"
        );
        let err = read_params_file(&dir.join("missing.yaml"), "/x")
            .unwrap_err()
            .to_string();
        assert!(err.contains("missing.yaml"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A file parameter's loader runs when the value is set, by the setter (the
    /// parameter services), before the change is announced; the loop reads the result.
    #[test]
    fn a_file_parameter_is_loaded_by_whoever_sets_it_and_kept_if_it_fails() {
        fn length(path: &str) -> Result<Loaded, String> {
            match path {
                "" => Ok(Arc::new(0usize)),
                p if p.starts_with("bad") => Err(format!("{p} does not load")),
                p => Ok(Arc::new(p.len())),
            }
        }
        let params = Params::new(BTreeMap::from([(
            "file".to_string(),
            ParameterValue::String(String::new()),
        )]));
        let mut changes = params.subscribe();
        params.load_with("file", length).unwrap();
        assert_eq!(params.loaded::<usize>("file").as_deref(), Some(&0));
        assert!(params.loaded::<String>("file").is_none(), "another type");
        assert!(params.loaded::<usize>("other").is_none(), "no loader");
        params.set("file", ParameterValue::String("abcd".into()));
        assert!(changes.has_changed().unwrap());
        changes.borrow_and_update();
        assert_eq!(params.loaded::<usize>("file").as_deref(), Some(&4));
        // a file that no longer loads keeps what was loaded before
        params.set("file", ParameterValue::String("bad.yaml".into()));
        assert_eq!(params.loaded::<usize>("file").as_deref(), Some(&4));
        // a loader refuses the start as it is
        let bad = Params::new(BTreeMap::from([(
            "file".to_string(),
            ParameterValue::String("bad-start".into()),
        )]));
        assert!(bad
            .load_with("file", length)
            .unwrap_err()
            .contains("bad-start"));
    }
}
