//! state_publisher's loop ([`state_publisher::run`]) through fake I/O: `joint_states`
//! in; `robot_description`, `tf_static`, `tf` and diagnostics out. Each wait is
//! bounded; nothing here asserts on timing.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::JointState;
use eezybot_msgs::tf2_msgs::TFMessage;
use futures::channel::mpsc;
use ros_plumbing::{ParameterValue, Params};
use state_publisher::{load_urdf, Handles, Input, Io, Outputs};
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// What the loop published, in order.
#[derive(Clone, Debug)]
enum Out {
    Tf(TFMessage),
    TfStatic(TFMessage),
    RobotDescription,
    Diagnostics(DiagnosticStatus),
}

#[derive(Default)]
struct Fake(Mutex<Vec<Out>>);

impl Outputs for Fake {
    fn tf(&self, msg: TFMessage) {
        self.0.lock().unwrap().push(Out::Tf(msg));
    }
    fn tf_static(&self, msg: TFMessage) {
        self.0.lock().unwrap().push(Out::TfStatic(msg));
    }
    fn robot_description(&self, _urdf: String) {
        self.0.lock().unwrap().push(Out::RobotDescription);
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.0.lock().unwrap().push(Out::Diagnostics(status));
    }
    fn joint_states_publishers(&self) -> usize {
        1
    }
}

impl Fake {
    fn out(&self) -> Vec<Out> {
        self.0.lock().unwrap().clone()
    }

    /// The newest diagnostics value of `key`.
    fn value(&self, key: &str) -> Option<String> {
        self.out().iter().rev().find_map(|o| match o {
            Out::Diagnostics(d) => Some(
                d.values
                    .iter()
                    .find(|kv| kv.key == key)
                    .map(|kv| kv.value.clone()),
            ),
            _ => None,
        })?
    }

    /// (child frame, z translation: the slider's axis) of every transform of the tf
    /// messages so far.
    fn tf_frames(&self) -> Vec<Vec<(String, f64)>> {
        self.out()
            .iter()
            .filter_map(|o| match o {
                Out::Tf(m) => Some(
                    m.transforms
                        .iter()
                        .map(|t| (t.child_frame_id.clone(), t.transform.translation.z))
                        .collect(),
                ),
                _ => None,
            })
            .collect()
    }
}

/// Wait until `pred` holds. The 30 s only bounds a failure: the loop runs on the real
/// clock, which a busy host (debug build, other test binaries beside this one) can hold
/// up for seconds.
async fn until(what: &str, pred: impl Fn() -> bool) {
    let end = Instant::now() + Duration::from_secs(30);
    while !pred() {
        assert!(Instant::now() < end, "never: {what}");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

fn slider(x: f64) -> Input {
    Input::JointStates(
        JointState {
            name: vec!["slider_joint".into()],
            position: vec![x],
            ..JointState::default()
        },
        Instant::now(),
    )
}

/// Run the loop on the test robot with these parameters while `script` runs.
async fn with_node<F: std::future::Future<Output = ()>>(
    params: &[(&str, ParameterValue)],
    script: impl FnOnce(&'static Fake, mpsc::UnboundedSender<Input>) -> F,
) {
    let urdf = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../tests/data/test_robot.urdf"
    );
    let fake: &'static Fake = Box::leak(Box::default());
    let (inputs, samples) = mpsc::unbounded::<Input>();
    let (stop, stopped) = futures::channel::oneshot::channel::<()>();
    let values: BTreeMap<String, ParameterValue> = params
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    let handles = Handles {
        description: load_urdf(urdf).unwrap(),
        io: Io {
            outputs: fake,
            params: Params::new(values),
            diag_name: "state_publisher: robot state".into(),
            joint_states_topic: "/joint_states".into(),
        },
        inputs: samples,
        shutdown: async move {
            let _ = stopped.await;
        },
    };
    let script = async move {
        script(fake, inputs).await;
        stop.send(()).unwrap();
    };
    futures::join!(state_publisher::run(handles), script);
}

#[tokio::test]
async fn every_sample_becomes_a_tf_with_the_prefix_and_bad_ones_are_counted() {
    with_node(
        &[("frame_prefix", ParameterValue::String("r1/".into()))],
        |fake, inputs| async move {
            // first the description, then its fixed joints
            let out = fake.out();
            assert!(matches!(out[0], Out::RobotDescription), "{out:?}");
            let Out::TfStatic(statics) = &out[1] else {
                panic!("{out:?}")
            };
            assert_eq!(statics.transforms[0].child_frame_id, "r1/mount");
            for x in [0.1, 0.2] {
                inputs.unbounded_send(slider(x)).unwrap();
            }
            inputs
                .unbounded_send(Input::Unreadable("bad CDR".into()))
                .unwrap();
            until("two tf messages", || fake.tf_frames().len() == 2).await;
            let frames = fake.tf_frames();
            assert_eq!(frames[0], [("r1/carriage".to_string(), 0.1)]);
            assert_eq!(frames[1], [("r1/carriage".to_string(), 0.2)]);
            until("the unreadable sample in diagnostics", || {
                fake.value("unreadable_samples").as_deref() == Some("1")
            })
            .await;
        },
    )
    .await;
}

#[tokio::test]
async fn with_a_publish_frequency_samples_between_two_messages_are_merged() {
    // one message every 2 s: the first sample goes at once, the next ones wait, merged
    with_node(
        &[("publish_frequency", ParameterValue::Double(0.5))],
        |fake, inputs| async move {
            for x in [0.1, 0.2, 0.3] {
                inputs.unbounded_send(slider(x)).unwrap();
            }
            until("the merged message", || fake.tf_frames().len() == 2).await;
            let frames = fake.tf_frames();
            assert_eq!(frames[0], [("carriage".to_string(), 0.1)]);
            assert_eq!(frames[1], [("carriage".to_string(), 0.3)], "the newest");
        },
    )
    .await;
}
