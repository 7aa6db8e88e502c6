//! wan/'s `CROSSING` (which topics cross the WAN bridge, from which side to which)
//! against the topic contract ([`ros_plumbing::topics`]). wan/ is a workspace of its
//! own (it builds Zenoh), so its table lives in a file of pure constants that
//! ros_plumbing includes ([`ros_plumbing::crossing`]).

use ros_plumbing::crossing::{Side, CROSSING};
use ros_plumbing::sros2::{node_of, EITHER_HALF, PC_NODES, PI_NODES};
use ros_plumbing::topics::{self, TopicEntry};

/// The sides a role of the contract runs on: the PC's nodes (compute_ik,
/// state_publisher, gui_bridge) on the PC, serial_node on the Pi, a leader arm's reader
/// on either.
fn sides(role: &str) -> Vec<Side> {
    if EITHER_HALF.contains(&role) {
        return vec![Side::Pc, Side::Pi];
    }
    let node = node_of(role);
    if PC_NODES.contains(&node) {
        vec![Side::Pc]
    } else if PI_NODES.contains(&node) {
        vec![Side::Pi]
    } else {
        panic!("{role} runs on neither side")
    }
}

fn runs_on(roles: &[&str], side: Side) -> bool {
    roles.iter().any(|r| sides(r).contains(&side))
}

fn entry(name: &str) -> TopicEntry {
    topics::all()
        .into_iter()
        .find(|t| t.name == name)
        .unwrap_or_else(|| panic!("{name} crosses the WAN but is not a topic of the contract"))
}

#[test]
fn every_crossing_topic_is_published_where_it_comes_from_and_subscribed_where_it_goes() {
    let mut names: Vec<&str> = CROSSING.iter().map(|c| c.topic).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), CROSSING.len(), "one crossing per topic");
    for c in CROSSING {
        let t = entry(c.topic);
        assert!(
            runs_on(t.publishers, c.from),
            "{} crosses from the {} but no node of ours publishes it there ({:?})",
            c.topic,
            c.from.name(),
            t.publishers
        );
        assert!(!c.to.is_empty(), "{} goes nowhere", c.topic);
        for &to in c.to {
            assert!(
                runs_on(t.subscribers, to),
                "{} crosses to the {} but no node of ours subscribes it there ({:?})",
                c.topic,
                to.name(),
                t.subscribers
            );
        }
    }
}

#[test]
fn every_topic_published_on_one_side_and_subscribed_on_the_other_crosses() {
    for t in topics::all() {
        // a role of either side (the leader's reader) is on the side it is used on
        let fixed = |roles: &[&'static str], side: Side| {
            roles
                .iter()
                .any(|r| !EITHER_HALF.contains(r) && sides(r) == [side])
        };
        for (from, to) in [(Side::Pc, Side::Pi), (Side::Pi, Side::Pc)] {
            if fixed(t.publishers, from) && fixed(t.subscribers, to) {
                assert!(
                    CROSSING
                        .iter()
                        .any(|c| c.topic == t.name && c.from == from && c.to.contains(&to)),
                    "{} is published on the {} and subscribed on the {}: it must cross \
                     (wan/src/crossing.rs)",
                    t.name,
                    from.name(),
                    to.name()
                );
            }
        }
    }
}
