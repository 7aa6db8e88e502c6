//! ROS name expansion and remapping (rcl's rules, for topic names).
//!
//! ros2-client turns a relative name in the root namespace into `rt//x`; we never
//! hand it a relative name: every topic is expanded to an absolute name here first.

use crate::args::Remap;
use crate::error::PlumbingError;

fn name_error(name: &str, why: &str) -> PlumbingError {
    PlumbingError::Name {
        name: name.to_string(),
        why: why.to_string(),
    }
}

fn valid_token(tok: &str) -> bool {
    let mut chars = tok.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && tok.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !tok.contains("__")
}

/// Check a namespace and put it in canonical form: absolute, no trailing slash
/// (except `/` itself). A relative namespace is taken from the root, as rcl does.
pub fn canonical_namespace(ns: &str) -> Result<String, PlumbingError> {
    let trimmed = ns.trim_end_matches('/');
    if trimmed.is_empty() {
        return Ok("/".into());
    }
    let body = trimmed.strip_prefix('/').unwrap_or(trimmed);
    if !body.split('/').all(valid_token) {
        return Err(name_error(
            ns,
            "a namespace is /-separated tokens of letters, digits and single underscores",
        ));
    }
    Ok(format!("/{body}"))
}

/// Check a node name (one token).
pub fn check_node_name(name: &str) -> Result<(), PlumbingError> {
    if valid_token(name) {
        Ok(())
    } else {
        Err(name_error(name, "a node name is one token of letters, digits and single underscores, not starting with a digit"))
    }
}

/// Expands and remaps topic names for one node.
#[derive(Clone, Debug)]
pub struct Resolver {
    namespace: String,
    node_name: String,
    /// (absolute from, absolute to)
    rules: Vec<(String, String)>,
}

impl Resolver {
    /// A resolver for the node `node_name` in `namespace`, with the remap rules that
    /// apply to it (`original_name` is the name the program gave the node, before `__node`).
    pub fn new(
        namespace: &str,
        node_name: &str,
        original_name: &str,
        remaps: &[Remap],
    ) -> Result<Resolver, PlumbingError> {
        let namespace = canonical_namespace(namespace)?;
        check_node_name(node_name)?;
        let mut r = Resolver {
            namespace,
            node_name: node_name.to_string(),
            rules: Vec::new(),
        };
        for rule in remaps {
            if let Some(node) = &rule.node {
                if node != node_name && node != original_name {
                    continue;
                }
            }
            let from = r.expand(&rule.from)?;
            let to = r.expand(&rule.to)?;
            r.rules.push((from, to));
        }
        Ok(r)
    }

    /// The node's namespace, canonical.
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The node's name.
    pub fn node_name(&self) -> &str {
        &self.node_name
    }

    /// Fully qualified node name, e.g. `/arm2/compute_ik`.
    pub fn node_fqn(&self) -> String {
        join(&self.namespace, &self.node_name)
    }

    /// Expand a name to an absolute one: `x` → `/ns/x`, `~/x` → `/ns/node/x`, `/x` stays.
    ///
    /// # Examples
    /// ```
    /// use ros_plumbing::names::Resolver;
    /// let r = Resolver::new("/", "compute_ik", "compute_ik", &[]).unwrap();
    /// assert_eq!(r.expand("xyz_target").unwrap(), "/xyz_target");
    /// let r = Resolver::new("/arm2", "compute_ik", "compute_ik", &[]).unwrap();
    /// assert_eq!(r.expand("xyz_target").unwrap(), "/arm2/xyz_target");
    /// assert_eq!(r.expand("~/status").unwrap(), "/arm2/compute_ik/status");
    /// assert_eq!(r.expand("/tf").unwrap(), "/tf");
    /// ```
    pub fn expand(&self, name: &str) -> Result<String, PlumbingError> {
        let expanded = if name == "~" {
            self.node_fqn()
        } else if let Some(rest) = name.strip_prefix("~/") {
            join(&self.node_fqn(), rest)
        } else if name.starts_with('/') {
            name.to_string()
        } else {
            join(&self.namespace, name)
        };
        let body = expanded.strip_prefix('/').unwrap_or(&expanded);
        if body.is_empty() || !body.split('/').all(valid_token) {
            return Err(name_error(
                name,
                "a topic name is /-separated tokens of letters, digits and single underscores",
            ));
        }
        Ok(expanded)
    }

    /// Expand `name`, then apply the first remap rule whose (expanded) source matches.
    pub fn resolve(&self, name: &str) -> Result<String, PlumbingError> {
        let expanded = self.expand(name)?;
        Ok(self
            .rules
            .iter()
            .find(|(from, _)| *from == expanded)
            .map(|(_, to)| to.clone())
            .unwrap_or(expanded))
    }
}

fn join(ns: &str, name: &str) -> String {
    if ns == "/" {
        format!("/{name}")
    } else {
        format!("{ns}/{name}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn remap(node: Option<&str>, from: &str, to: &str) -> Remap {
        Remap {
            node: node.map(str::to_string),
            from: from.into(),
            to: to.into(),
        }
    }

    #[test]
    fn remaps_match_after_expansion() {
        let rules = [
            remap(None, "xyz_target", "goal"),
            remap(None, "/arm2/servo_angles", "/angles"),
        ];
        let r = Resolver::new("/arm2", "compute_ik", "compute_ik", &rules).unwrap();
        assert_eq!(r.resolve("xyz_target").unwrap(), "/arm2/goal");
        assert_eq!(r.resolve("servo_angles").unwrap(), "/angles");
        assert_eq!(r.resolve("joint_states").unwrap(), "/arm2/joint_states");
    }

    #[test]
    fn node_specific_rules_apply_to_their_node_only() {
        let rules = [
            remap(Some("other"), "a", "b"),
            remap(Some("compute_ik"), "c", "d"),
        ];
        let r = Resolver::new("/", "renamed", "compute_ik", &rules).unwrap();
        assert_eq!(r.resolve("a").unwrap(), "/a");
        assert_eq!(r.resolve("c").unwrap(), "/d");
    }

    #[test]
    fn canonical_namespaces() {
        assert_eq!(canonical_namespace("").unwrap(), "/");
        assert_eq!(canonical_namespace("/").unwrap(), "/");
        assert_eq!(canonical_namespace("arm2/").unwrap(), "/arm2");
        assert_eq!(canonical_namespace("/a/b").unwrap(), "/a/b");
        assert!(canonical_namespace("/a b").is_err());
        assert!(canonical_namespace("/2arm").is_err());
    }

    #[test]
    fn bad_topic_names_are_refused() {
        let r = Resolver::new("/", "n", "n", &[]).unwrap();
        for bad in ["", "a//b", "a-b", "9x", "/"] {
            assert!(r.expand(bad).is_err(), "{bad}");
        }
    }
}
