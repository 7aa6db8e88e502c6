//! JSON objects written with their keys in a given order (lerobot writes info.json from a
//! dataclass, in field order) and indented by 4 as Python's `json.dump(..., indent=4)`.

use serde::ser::{Serialize, SerializeMap, SerializeSeq, Serializer};
use serde_json::Value;

/// A JSON value whose objects keep the order their keys were given in.
#[derive(Debug, Clone)]
pub enum Ordered {
    /// An object, keys in order.
    Obj(Vec<(String, Ordered)>),
    /// An array.
    Arr(Vec<Ordered>),
    /// A scalar (or any value whose key order does not matter).
    Val(Value),
}

impl Ordered {
    /// An object from `(key, value)` pairs.
    pub fn obj<K: Into<String>>(pairs: impl IntoIterator<Item = (K, Ordered)>) -> Self {
        Ordered::Obj(pairs.into_iter().map(|(k, v)| (k.into(), v)).collect())
    }

    /// A scalar or plain value.
    pub fn val(v: impl Into<Value>) -> Self {
        Ordered::Val(v.into())
    }

    /// Pretty-printed as Python's `json.dump(data, f, indent=4, ensure_ascii=False)`.
    pub fn to_pretty(&self) -> Vec<u8> {
        let mut out = Vec::new();
        let fmt = serde_json::ser::PrettyFormatter::with_indent(b"    ");
        let mut ser = serde_json::Serializer::with_formatter(&mut out, fmt);
        // writing to a Vec cannot fail, nor can serialising finite numbers and strings
        if self.serialize(&mut ser).is_err() {
            out.clear();
        }
        out
    }
}

impl Serialize for Ordered {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Ordered::Obj(pairs) => {
                let mut m = s.serialize_map(Some(pairs.len()))?;
                for (k, v) in pairs {
                    m.serialize_entry(k, v)?;
                }
                m.end()
            }
            Ordered::Arr(items) => {
                let mut q = s.serialize_seq(Some(items.len()))?;
                for v in items {
                    q.serialize_element(v)?;
                }
                q.end()
            }
            Ordered::Val(v) => v.serialize(s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_order_and_indents_by_four() {
        let o = Ordered::obj([
            ("z", Ordered::val(1)),
            ("a", Ordered::Arr(vec![Ordered::val("x")])),
        ]);
        let s = String::from_utf8(o.to_pretty()).unwrap();
        assert_eq!(s, "{\n    \"z\": 1,\n    \"a\": [\n        \"x\"\n    ]\n}");
    }
}
