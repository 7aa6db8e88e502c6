//! Parameter values from YAML (a `-p name:=value` argument, a `--params-file`), typed as
//! rcl types them. A module of its own so that `args` (the command line) and `params`
//! (the declared parameters) both use it without depending on each other.

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
    let all = |f: fn(&ParameterValue) -> bool| items.iter().all(f);
    Ok(if items.is_empty() {
        ParameterValue::StringArray(vec![])
    } else if all(|p| matches!(p, ParameterValue::Boolean(_))) {
        ParameterValue::BooleanArray(
            items
                .iter()
                .filter_map(|p| {
                    if let ParameterValue::Boolean(b) = p {
                        Some(*b)
                    } else {
                        None
                    }
                })
                .collect(),
        )
    } else if all(|p| matches!(p, ParameterValue::Integer(_))) {
        ParameterValue::IntegerArray(
            items
                .iter()
                .filter_map(|p| {
                    if let ParameterValue::Integer(i) = p {
                        Some(*i)
                    } else {
                        None
                    }
                })
                .collect(),
        )
    } else if all(|p| matches!(p, ParameterValue::Integer(_) | ParameterValue::Double(_))) {
        ParameterValue::DoubleArray(
            items
                .iter()
                .filter_map(|p| match p {
                    ParameterValue::Integer(i) => Some(*i as f64),
                    ParameterValue::Double(d) => Some(*d),
                    _ => None,
                })
                .collect(),
        )
    } else if all(|p| matches!(p, ParameterValue::String(_))) {
        ParameterValue::StringArray(
            items
                .iter()
                .filter_map(|p| {
                    if let ParameterValue::String(s) = p {
                        Some(s.clone())
                    } else {
                        None
                    }
                })
                .collect(),
        )
    } else {
        return Err("arrays must hold scalars of one type".into());
    })
}
