//! MCAP recordings written and read back.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::std_msgs::Float64;
use foxglove_bridge::{ros2msg_schema, McapRecorder, McapTargets, TopicNames, TOPICS};
use std::collections::HashMap;
use std::io::Cursor;

fn xyz(x: f64) -> Vec<u8> {
    eezybot_msgs::cdr::encode(&PointStamped {
        point: Point { x, y: 0.0, z: 0.1 },
        ..Default::default()
    })
    .unwrap()
}

fn record(names: &TopicNames) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut rec = McapRecorder::new(Cursor::new(&mut bytes), names).unwrap();
    assert!(rec.write("xyz_target", &xyz(0.1), 1_000_000_000).unwrap());
    assert!(rec
        .write("joint_states", &[0, 1, 0, 0, 1, 2, 3, 4], 1_100_000_000)
        .unwrap());
    let g = eezybot_msgs::cdr::encode(&Float64 { data: 0.5 }).unwrap();
    assert!(rec.write("gripper_target", &g, 1_200_000_000).unwrap());
    assert!(rec.write("xyz_target", &xyz(0.2), 1_500_000_000).unwrap());
    // not recorded
    assert!(!rec
        .write("diagnostics", &[0, 1, 0, 0], 1_300_000_000)
        .unwrap());
    assert!(!rec
        .write("no_such_topic", &[0, 1, 0, 0], 1_300_000_000)
        .unwrap());
    assert_eq!(rec.finish().unwrap(), 4);
    bytes
}

#[test]
fn a_recording_has_every_recorded_topic_with_its_ros2msg_schema() {
    let bytes = record(&TopicNames::default());
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let by_topic: HashMap<&str, _> = summary
        .channels
        .values()
        .map(|c| (c.topic.as_str(), c.clone()))
        .collect();
    for t in TOPICS {
        let Some(c) = by_topic.get(format!("/{}", t.topic).as_str()) else {
            assert!(!t.recorded, "{} missing", t.topic);
            continue;
        };
        assert!(t.recorded, "{} should not be recorded", t.topic);
        assert_eq!(c.message_encoding, "cdr");
        let schema = c.schema.as_ref().unwrap();
        assert_eq!(
            (schema.name.as_str(), schema.encoding.as_str()),
            (t.type_name, "ros2msg")
        );
        assert_eq!(
            &schema.data[..],
            ros2msg_schema(t.type_name).unwrap().as_bytes()
        );
    }
    let stats = summary.stats.unwrap();
    assert_eq!(stats.message_count, 4);
    assert_eq!(stats.message_start_time, 1_000_000_000);
    assert_eq!(stats.message_end_time, 1_500_000_000);
}

#[test]
fn targets_come_back_in_order_with_their_times_and_bytes() {
    let bytes = record(&TopicNames::in_namespace("/arm2"));
    let targets = McapTargets::from_bytes(&bytes).unwrap();
    let got: Vec<(&str, u64)> = targets
        .targets()
        .iter()
        .map(|t| (t.topic, t.log_time_ns))
        .collect();
    assert_eq!(
        got,
        [
            ("xyz_target", 1_000_000_000),
            ("gripper_target", 1_200_000_000),
            ("xyz_target", 1_500_000_000)
        ]
    );
    assert_eq!(targets.targets()[2].cdr, xyz(0.2));
}

#[test]
fn a_file_that_is_not_mcap_is_an_error_not_a_panic() {
    assert!(McapTargets::from_bytes(b"x,y,z\n0.1,0,0.1\n").is_err());
    assert!(McapTargets::from_bytes(&[]).is_err());
    let mut truncated = record(&TopicNames::default());
    truncated.truncate(truncated.len() / 2);
    let _ = McapTargets::from_bytes(&truncated);
}
