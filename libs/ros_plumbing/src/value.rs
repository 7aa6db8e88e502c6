//! Parameter values from YAML (a `-p name:=value` argument, a `--params-file`), typed as
//! rcl types them, and the Rust types of parameter values ([`ParamType`]). A module of
//! its own so that `args` (the command line), `params` (the declared parameters) and
//! `remote_params` (another node's) use it without depending on each other.

use ros2_client::ParameterValue;

/// A YAML scalar or list as a parameter value, typed as rcl types it.
pub(crate) fn yaml_to_parameter(v: &serde_norway::Value) -> Result<ParameterValue, String> {
    use serde_norway::Value as Y;
    let scalar = |v: &Y| -> Result<ParameterValue, String> {
        match v {
            Y::Bool(b) => Ok(ParameterValue::Boolean(*b)),
            Y::Number(n) => match n.as_i64() {
                Some(i) => Ok(ParameterValue::Integer(i)),
                None => n
                    .as_f64()
                    .map(ParameterValue::Double)
                    .ok_or_else(|| format!("number {n} out of range")),
            },
            Y::String(s) => Ok(ParameterValue::String(s.clone())),
            Y::Null => Err("a parameter value cannot be null".into()),
            Y::Tagged(t) => Err(format!("unsupported YAML tag {}", t.tag)),
            Y::Sequence(_) | Y::Mapping(_) => Err("arrays must hold scalars of one type".into()),
        }
    };
    let Y::Sequence(items) = v else {
        return scalar(v);
    };
    let items: Vec<ParameterValue> = items.iter().map(scalar).collect::<Result<_, _>>()?;
    let doubles = items.iter().map(|p| match p {
        ParameterValue::Integer(i) => Some(*i as f64),
        ParameterValue::Double(d) => Some(*d),
        _ => None,
    });
    Ok(if items.is_empty() {
        ParameterValue::StringArray(vec![])
    } else if let Some(b) = every::<bool>(&items) {
        ParameterValue::BooleanArray(b)
    } else if let Some(i) = every::<i64>(&items) {
        ParameterValue::IntegerArray(i)
    } else if let Some(d) = doubles.collect::<Option<Vec<f64>>>() {
        ParameterValue::DoubleArray(d)
    } else if let Some(s) = every::<String>(&items) {
        ParameterValue::StringArray(s)
    } else {
        return Err("arrays must hold scalars of one type".into());
    })
}

/// The items, if every one is a `T`.
fn every<T: ParamType>(items: &[ParameterValue]) -> Option<Vec<T>> {
    items
        .iter()
        .map(|p| T::from_value(p.clone()).ok())
        .collect()
}

/// A Rust type that is one ROS 2 parameter type.
pub trait ParamType: Sized {
    /// The ROS 2 type's name, for errors (`string`).
    const NAME: &'static str;
    /// As a parameter value.
    fn into_value(self) -> ParameterValue;
    /// From a parameter value of this type; the value back otherwise.
    fn from_value(value: ParameterValue) -> Result<Self, ParameterValue>;
}

macro_rules! param_type {
    ($t:ty, $variant:ident, $name:literal) => {
        impl ParamType for $t {
            const NAME: &'static str = $name;
            fn into_value(self) -> ParameterValue {
                ParameterValue::$variant(self)
            }
            fn from_value(value: ParameterValue) -> Result<Self, ParameterValue> {
                match value {
                    ParameterValue::$variant(v) => Ok(v),
                    other => Err(other),
                }
            }
        }
    };
}
param_type!(bool, Boolean, "bool");
param_type!(i64, Integer, "integer");
param_type!(f64, Double, "double");
param_type!(String, String, "string");
param_type!(Vec<String>, StringArray, "string array");

#[cfg(test)]
mod tests {
    use super::*;

    fn typed(yaml: &str) -> Result<ParameterValue, String> {
        yaml_to_parameter(&serde_norway::from_str(yaml).map_err(|e| e.to_string())?)
    }

    #[test]
    fn lists_are_typed_as_rcl_types_them() {
        use ParameterValue as P;
        assert_eq!(typed("[]"), Ok(P::StringArray(vec![])));
        assert_eq!(
            typed("[true, false]"),
            Ok(P::BooleanArray(vec![true, false]))
        );
        assert_eq!(typed("[1, -2]"), Ok(P::IntegerArray(vec![1, -2])));
        assert_eq!(typed("[1, 2.5]"), Ok(P::DoubleArray(vec![1.0, 2.5])));
        assert_eq!(
            typed("[a, b]"),
            Ok(P::StringArray(vec!["a".into(), "b".into()]))
        );
        assert!(typed("[1, a]").is_err());
        assert!(typed("[true, 1]").is_err());
        assert_eq!(typed("3"), Ok(P::Integer(3)));
    }
}
