//! compute_ik's loop ([`compute_ik::run`]) through fake outputs: the order between a
//! parameter set and an input sent after its answer. Each wait is bounded; nothing
//! here asserts on timing.
#![allow(clippy::unwrap_used, clippy::expect_used)]
use compute_ik::driver::{Effect, ReaderId};
use compute_ik::eezybot::IkCore;
use compute_ik::{Handles, Input, Outputs};
use eezybot_kinematics::ArmConfig;
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::geometry_msgs::{Point, PointStamped};
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::std_msgs::Header;
use eezybot_msgs::Time;
use futures::channel::mpsc;
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::{ParameterValue, Params};
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[derive(Default)]
struct Fake {
    joint_states: Mutex<Vec<JointState>>,
    diagnostics: Mutex<Vec<DiagnosticStatus>>,
}

impl Outputs for &Fake {
    fn joint_states(&self, msg: JointState) {
        self.joint_states.lock().unwrap().push(msg);
    }
    fn servo_angles(&self, _msg: JointState) {}
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.lock().unwrap().push(status);
    }
    fn controllers(&self, _effect: Effect) {}
    fn peer_counts(&self) -> [usize; 3] {
        [1, 1, 1]
    }
    fn joint_states_readers(&self) -> Vec<ReaderId> {
        vec![]
    }
}

impl Fake {
    /// The newest diagnostics value of `key`, as a count.
    fn count(&self, key: &str) -> u64 {
        let d = self.diagnostics.lock().unwrap();
        d.last()
            .and_then(|s| s.values.iter().find(|kv| kv.key == key))
            .and_then(|kv| kv.value.parse().ok())
            .unwrap_or(0)
    }
}

/// Wait until `pred` holds (the 30 s only bound a failure).
async fn until(what: &str, pred: impl Fn() -> bool) {
    let end = Instant::now() + Duration::from_secs(30);
    while !pred() {
        assert!(Instant::now() < end, "never: {what}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// A parameter set before a target was sent applies before it, whichever the loop
/// wakes to first. Each round makes both ready before the loop runs again (no await
/// between them): `max_target_age` at 1 s, then a target stamped 5 s ago, refused as
/// stale; the limit off (0), then the same target, taken.
#[tokio::test]
async fn a_target_sent_after_a_parameter_was_set_is_judged_by_the_new_value() {
    let values: BTreeMap<String, ParameterValue> = compute_ik::spec()
        .params
        .iter()
        .map(|s| (s.name.to_string(), s.default.clone()))
        .collect();
    let params = Params::new(values);
    let fake = Fake::default();
    let (inputs, samples) = mpsc::unbounded::<Input>();
    let (stop, stopped) = futures::channel::oneshot::channel::<()>();
    let handles = Handles {
        inputs: samples,
        outputs: &fake,
        params: params.clone(),
        peers: PeerWatch::new(&compute_ik::watched_topics(
            "/servo_angles",
            "/joint_states",
            "/xyz_target",
        )),
        diag_name: "compute_ik: inverse kinematics".into(),
        shutdown: async move {
            let _ = stopped.await;
        },
    };
    let old_target = |k: f64| {
        Input::XyzTarget(PointStamped {
            header: Header {
                stamp: Time::from_nanos(Time::now().to_nanos() - 5_000_000_000),
                frame_id: String::new(),
            },
            point: Point {
                x: 0.2,
                y: 0.001 * k,
                z: 0.15,
            },
        })
    };
    let script = async {
        for round in 0..20 {
            let (refused, taken) = (fake.count("stale"), fake.joint_states.lock().unwrap().len());
            params.set("max_target_age", ParameterValue::Double(1.0));
            inputs.unbounded_send(old_target(round as f64)).unwrap();
            until("the old target refused as stale", || {
                fake.count("stale") == refused + 1
            })
            .await;
            assert_eq!(
                fake.joint_states.lock().unwrap().len(),
                taken,
                "round {round}"
            );
            params.set("max_target_age", ParameterValue::Double(0.0));
            inputs.unbounded_send(old_target(round as f64)).unwrap();
            until("the same target taken with no age limit", || {
                fake.joint_states.lock().unwrap().len() > taken
            })
            .await;
            assert_eq!(fake.count("stale"), refused + 1, "round {round}");
        }
        stop.send(()).unwrap();
    };
    let core = IkCore::new(&ArmConfig::default(), "base_link");
    let ((), ()) = futures::join!(compute_ik::run(core, handles), script);
}
