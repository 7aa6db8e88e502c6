//! The router's access control (least privilege): each client certificate has a role,
//! its subject's common name (`pc` or `pi`, [`Side::name`]; `launch_scripts/wan_certs.sh`
//! issues them so), and each role may send into the router only its own side's
//! directions of [`CROSSING`] and receive only what its side takes. Anything else is
//! refused (Zenoh's `access_control`, default deny): a client holding a Pi's
//! certificate cannot publish `servo_angles`, nor subscribe to `robot_description`.
//!
//! What the bridges (zenoh-plugin-ros2dds) exchange, per crossing topic `T` (in any
//! namespace: `T` or `NS/T`, so each key is `**/T`):
//! - data: `put` on `T`, from the publishing side's bridge (ingress) to each taking side's
//!   (egress); subscriber declarations the other way (a publisher sends only where the
//!   router says a subscriber is);
//! - transient-local history (`estop`, `robot_description`: zenoh-ext's advanced
//!   publisher and subscriber): the publisher's cache queryable and liveliness token under
//!   `T/@adv/**`, the late subscriber's queries and liveliness subscription there, and the
//!   replies (samples on `T`). Granted for every crossing topic in its own direction; only
//!   the transient-local ones use it;
//! - route discovery: liveliness tokens `@/<zid>/@ros2_lv/…`, queried and subscribed by
//!   every bridge (no data: a token only announces a route), for both roles.
//!
//! `**` does not match chunks that begin with `@`, so the `@adv` and `@ros2_lv` keys are
//! named explicitly. Nothing else is granted: no other key, no `delete`, no admin space.
//!
//! [`CROSSING`]: crate::CROSSING

use crate::{json, Side};

/// The two roles, each a certificate common name.
pub const ROLES: [Side; 2] = [Side::Pc, Side::Pi];

/// Liveliness keys of the plugin's route discovery.
const DISCOVERY: &str = "@/*/@ros2_lv/**";

fn data_key(topic: &str) -> String {
    format!("**/{topic}")
}

fn history_key(topic: &str) -> String {
    format!("**/{topic}/@adv/**")
}

/// One rule: `flow` (`ingress`: from the client into the router; `egress`: from the
/// router to the client), the messages it allows, on these keys.
struct Rule {
    id: String,
    flow: &'static str,
    messages: &'static [&'static str],
    keys: Vec<String>,
}

impl Rule {
    fn json5(&self) -> String {
        let list = |v: &mut dyn Iterator<Item = String>| v.collect::<Vec<_>>().join(", ");
        format!(
            "{{ id: {}, permission: \"allow\", flows: [{}], messages: [{}], key_exprs: [{}] }}",
            json(&self.id),
            json(self.flow),
            list(&mut self.messages.iter().map(json)),
            list(&mut self.keys.iter().map(json)),
        )
    }
}

/// The rules of one role.
fn rules(role: Side) -> Vec<Rule> {
    let name = role.name();
    let out = role.outgoing();
    let inc = role.incoming();
    let keys = |topics: &[&str], f: fn(&str) -> String| -> Vec<String> {
        topics.iter().map(|t| f(t)).collect()
    };
    let both = |topics: &[&str]| -> Vec<String> {
        topics
            .iter()
            .flat_map(|t| [data_key(t), history_key(t)])
            .collect()
    };
    let mut r = vec![
        Rule {
            id: format!("{name}-discovery-in"),
            flow: "ingress",
            messages: &[
                "liveliness_token",
                "liveliness_query",
                "declare_liveliness_subscriber",
            ],
            keys: vec![DISCOVERY.to_string()],
        },
        Rule {
            id: format!("{name}-discovery-out"),
            flow: "egress",
            messages: &["liveliness_token", "declare_liveliness_subscriber"],
            keys: vec![DISCOVERY.to_string()],
        },
    ];
    if !out.is_empty() {
        r.extend([
            // its samples, and the replies of its history cache
            Rule {
                id: format!("{name}-publish"),
                flow: "ingress",
                messages: &["put", "reply"],
                keys: keys(&out, data_key),
            },
            Rule {
                id: format!("{name}-publish-history"),
                flow: "ingress",
                messages: &["declare_queryable", "liveliness_token", "reply"],
                keys: keys(&out, history_key),
            },
            // where its subscribers are; late subscribers' queries to its cache
            Rule {
                id: format!("{name}-publish-matching"),
                flow: "egress",
                messages: &["declare_subscriber"],
                keys: keys(&out, data_key),
            },
            Rule {
                id: format!("{name}-publish-queries"),
                flow: "egress",
                messages: &["query", "declare_liveliness_subscriber"],
                keys: keys(&out, history_key),
            },
        ]);
    }
    if !inc.is_empty() {
        r.extend([
            Rule {
                id: format!("{name}-subscribe"),
                flow: "ingress",
                messages: &["declare_subscriber"],
                keys: keys(&inc, data_key),
            },
            Rule {
                id: format!("{name}-subscribe-history"),
                flow: "ingress",
                messages: &["query", "declare_liveliness_subscriber", "liveliness_query"],
                keys: keys(&inc, history_key),
            },
            Rule {
                id: format!("{name}-receive"),
                flow: "egress",
                messages: &["put", "reply"],
                keys: both(&inc),
            },
            Rule {
                id: format!("{name}-receive-history"),
                flow: "egress",
                messages: &["liveliness_token", "declare_queryable"],
                keys: keys(&inc, history_key),
            },
        ]);
    }
    r
}

/// The router's `access_control` configuration (JSON5): default deny, one subject per
/// role (its certificate common name), each role's rules.
pub fn access_control() -> String {
    let mut rule_list = Vec::new();
    let mut subjects = Vec::new();
    let mut policies = Vec::new();
    for role in ROLES {
        let name = role.name();
        let rs = rules(role);
        policies.push(format!(
            "{{ id: {}, subjects: [{}], rules: [{}] }}",
            json(format!("role-{name}")),
            json(name),
            rs.iter()
                .map(|r| json(&r.id))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        rule_list.extend(rs.iter().map(Rule::json5));
        subjects.push(format!(
            "{{ id: {}, cert_common_names: [{}] }}",
            json(name),
            json(name)
        ));
    }
    format!(
        "{{ enabled: true, default_permission: \"deny\", rules: [{}], subjects: [{}], policies: [{}] }}",
        rule_list.join(", "),
        subjects.join(", "),
        policies.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use zenoh::key_expr::KeyExpr;

    /// Whether `role` may send `message` in `flow` on `key` under [`rules`]: some rule's
    /// key includes it (Zenoh's decision with default deny and allow rules only).
    fn allowed(role: Side, flow: &str, message: &str, key: &str) -> bool {
        let key = KeyExpr::new(key).unwrap();
        rules(role).iter().any(|r| {
            r.flow == flow
                && r.messages.contains(&message)
                && r.keys
                    .iter()
                    .any(|k| KeyExpr::new(k.as_str()).unwrap().includes(&key))
        })
    }

    #[test]
    fn each_role_publishes_only_its_own_sides_topics() {
        for (role, key, ok) in [
            (Side::Pi, "servo_angles", false),
            (Side::Pi, "arm2/servo_angles", false),
            (Side::Pi, "estop", false),
            (Side::Pi, "robot_description", false),
            (Side::Pi, "servo_state", true),
            (Side::Pi, "arm2/diagnostics", true),
            (Side::Pc, "servo_angles", true),
            (Side::Pc, "arm2/servo_angles", true),
            (Side::Pc, "estop", true),
            (Side::Pc, "robot_description", true),
            (Side::Pc, "servo_state", false),
            (Side::Pc, "diagnostics", false),
            (Side::Pc, "anything/else", false),
        ] {
            assert_eq!(
                allowed(role, "ingress", "put", key),
                ok,
                "{role:?} put {key}"
            );
        }
        for role in ROLES {
            for message in [
                "put",
                "delete",
                "query",
                "declare_queryable",
                "declare_subscriber",
            ] {
                // no wildcard grabs, no admin space
                for key in ["**", "@/**", "@/0123/ros2/**"] {
                    assert!(
                        !allowed(role, "ingress", message, key),
                        "{role:?} {message} {key}"
                    );
                }
            }
            assert!(!allowed(role, "ingress", "delete", "servo_state"));
        }
    }

    #[test]
    fn history_and_discovery_go_only_each_topics_way() {
        // a late Pi asks the PCs' estop cache, never the robot_description one
        assert!(allowed(Side::Pi, "ingress", "query", "estop/@adv/pub/**"));
        assert!(!allowed(
            Side::Pi,
            "ingress",
            "query",
            "robot_description/@adv/pub/**"
        ));
        assert!(allowed(Side::Pi, "egress", "reply", "estop"));
        assert!(!allowed(Side::Pi, "ingress", "reply", "estop"));
        assert!(!allowed(
            Side::Pi,
            "ingress",
            "declare_queryable",
            "estop/@adv/pub/ab/1/_"
        ));
        assert!(allowed(
            Side::Pc,
            "ingress",
            "declare_queryable",
            "estop/@adv/pub/ab/1/_"
        ));
        assert!(allowed(
            Side::Pc,
            "egress",
            "query",
            "arm2/estop/@adv/pub/**"
        ));
        // the Pi may not subscribe to what it does not take
        assert!(!allowed(
            Side::Pi,
            "ingress",
            "declare_subscriber",
            "robot_description"
        ));
        assert!(allowed(
            Side::Pi,
            "ingress",
            "declare_subscriber",
            "servo_angles"
        ));
        for role in ROLES {
            assert!(allowed(
                role,
                "ingress",
                "liveliness_token",
                "@/0a1b/@ros2_lv/MP/servo_angles/t/q"
            ));
            assert!(allowed(
                role,
                "ingress",
                "declare_liveliness_subscriber",
                "@/*/@ros2_lv/**"
            ));
            assert!(!allowed(role, "ingress", "put", "@/0a1b/@ros2_lv/MP/x"));
        }
    }

    #[test]
    fn zenoh_takes_the_configuration() {
        let mut c = zenoh::config::Config::default();
        c.insert_json5("access_control", &access_control()).unwrap();
    }
}
