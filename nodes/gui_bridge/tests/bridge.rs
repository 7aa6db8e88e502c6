//! The bridge loop under load: e-stops before queued requests; a client that does not
//! read its replies loses replies, never stalls the loop.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::Time;
use futures::StreamExt;
use gui_bridge::panel::Panel;
use gui_bridge::web::{
    request_channels, ClientRequest, FromClient, Limits, ProgramOp, RequestSenders, Requests,
    WebStats,
};
use gui_bridge::{Handles, Outputs, Reporting};
use ros_plumbing::peers::PeerWatch;
use ros_plumbing::Params;
use std::cell::RefCell;
use std::collections::BTreeMap;
use tokio::sync::{broadcast, mpsc, oneshot, watch};

/// Records e-stops with the number of replies the loop had given by then.
struct Fake {
    replies: mpsc::Sender<String>,
    capacity: usize,
    estops: RefCell<Vec<(bool, usize)>>,
    done: RefCell<Option<oneshot::Sender<()>>>,
}

impl Outputs for Fake {
    fn xyz_target(&self, _: [f64; 3], _: bool, _: Time) {}
    fn gripper_target(&self, _: f64) {}
    fn joint_target(&self, _: &[(String, f64)], _: Time) {}
    fn estop(&self, engaged: bool) {
        let answered = self.capacity - self.replies.capacity();
        self.estops.borrow_mut().push((engaged, answered));
        if let Some(done) = self.done.borrow_mut().take() {
            let _ = done.send(());
        }
    }
    fn diagnostics(&self, _: DiagnosticStatus) {}
}

use gui_bridge::desk::Desk;

/// A desk whose program files would go to a directory of this test's own.
fn desk() -> Desk {
    Desk::new(std::env::temp_dir().join(format!("gui_bridge_bridge_{}", std::process::id())))
}

fn panel() -> Panel {
    let arm = gui_bridge::load_arm("").unwrap();
    Panel::new(arm, 50.0, desk(), "gui_bridge")
}

/// The loop's ends for a test: no parameters to change, no compute_ik to set modes on,
/// browsers that hear nothing.
fn handles<'a, I, O, S>(
    inputs: I,
    requests: Requests,
    outputs: &'a O,
    shutdown: S,
) -> Handles<'a, I, O, impl Fn() -> Vec<usize>, S> {
    Handles {
        inputs,
        requests,
        web: WebStats::default(),
        to_browsers: broadcast::channel(16).0,
        snapshot: watch::channel(panel().snapshot()).0,
        outputs,
        params: Params::new(BTreeMap::new()),
        reporting: Reporting {
            name: "gui_bridge: operator panel".into(),
            url: "http://127.0.0.1:8080/".into(),
            peers: PeerWatch::new(&[]),
            counts: Vec::new,
            transport: gui_bridge::tls::Transport::Plain,
        },
        calibration: &gui_bridge::NoCalibration,
        recorder: &gui_bridge::NoRecorder,
        camera: watch::channel(None).0,
        shutdown,
    }
}

/// Request channels with `n` reachability checks queued, answered on `reply`.
fn checks_queued(n: usize, reply: &mpsc::Sender<String>) -> (RequestSenders, Requests) {
    let limits = Limits {
        request_queue: n,
        ..Limits::default()
    };
    let (senders, requests) = request_channels(&limits);
    for i in 0..n {
        let request = ClientRequest::Check {
            xyz: [0.2, 0.0, 0.1 + i as f64 * 1e-5],
        };
        let reply = reply.clone();
        senders.try_send(FromClient { request, reply }).unwrap();
    }
    (senders, requests)
}

#[tokio::test]
async fn an_estop_is_served_before_a_thousand_queued_requests() {
    let (reply, mut replies) = mpsc::channel(1000);
    let (senders, requests) = checks_queued(1000, &reply);
    let (done_tx, done_rx) = oneshot::channel();
    let fake = Fake {
        replies: reply.clone(),
        capacity: 1000,
        estops: RefCell::new(vec![]),
        done: RefCell::new(Some(done_tx)),
    };
    senders
        .try_send(FromClient {
            request: ClientRequest::Estop { on: true },
            reply: reply.clone(),
        })
        .unwrap();
    gui_bridge::run(
        panel(),
        handles(futures::stream::pending(), requests, &fake, async {
            let _ = done_rx.await;
        }),
    )
    .await;
    let (engaged, answered) = fake.estops.borrow()[0];
    assert!(engaged);
    assert!(
        answered <= 1,
        "{answered} requests were answered before the e-stop went out"
    );
    // the e-stop's own acknowledgement is the first reply
    assert!(replies.recv().await.unwrap().contains("\"ack\""));
}

#[tokio::test]
async fn a_client_that_reads_nothing_loses_replies_and_stalls_nothing() {
    let (reply, _replies) = mpsc::channel(4); // never read
    let (_senders, requests) = checks_queued(100, &reply);
    let recorder = Recorder::default();
    let through = async {
        while recorder.last_value("dropped_replies").as_deref() != Some("96") {
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        }
    };
    let run = gui_bridge::run(
        panel(),
        handles(futures::stream::pending(), requests, &recorder, through),
    );
    tokio::time::timeout(std::time::Duration::from_secs(10), run)
        .await
        .expect("the loop stalled on a client that reads nothing");
}

/// Records what the loop publishes.
#[derive(Default)]
struct Recorder {
    joint_targets: RefCell<Vec<Vec<(String, f64)>>>,
    diagnostics: RefCell<Vec<DiagnosticStatus>>,
}

impl Outputs for Recorder {
    fn xyz_target(&self, _: [f64; 3], _: bool, _: Time) {}
    fn gripper_target(&self, _: f64) {}
    fn joint_target(&self, q: &[(String, f64)], _: Time) {
        self.joint_targets.borrow_mut().push(q.to_vec());
    }
    fn estop(&self, _: bool) {}
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.borrow_mut().push(status);
    }
}

impl Recorder {
    fn last_value(&self, key: &str) -> Option<String> {
        let d = self.diagnostics.borrow();
        let kv = d.last()?.values.iter().find(|kv| kv.key == key)?;
        Some(kv.value.clone())
    }
}

#[tokio::test]
async fn a_joint_target_it_cannot_check_is_refused_counted_and_never_published() {
    let (senders, requests) = request_channels(&Limits::default());
    let (reply, mut replies) = mpsc::channel(16);
    let joints = |q: &[(&str, f64)]| ClientRequest::Joints {
        q: q.iter().map(|(n, v)| (n.to_string(), *v)).collect(),
    };
    for request in [
        joints(&[("gripper_joint", 1e300)]),
        joints(&[]),
        joints(&[("base_joint", 0.1), ("wrist_joint", 0.0)]),
    ] {
        senders
            .try_send(FromClient {
                request,
                reply: reply.clone(),
            })
            .unwrap();
    }
    let inputs = futures::stream::iter([gui_bridge::Input::Unreadable {
        topic: "joint_states",
        error: "the sample ends early".into(),
    }])
    .chain(futures::stream::pending());
    let recorder = Recorder::default();
    let counted = async {
        while !(recorder.last_value("rejected").as_deref() == Some("3")
            && recorder.last_value("unreadable_samples").as_deref() == Some("1"))
        {
            tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        }
    };
    let run = gui_bridge::run(panel(), handles(inputs, requests, &recorder, counted));
    tokio::time::timeout(std::time::Duration::from_secs(10), run)
        .await
        .expect("no diagnostics counting the refusals and the unreadable sample");
    for says in [
        "gripper_joint = 1e300 is outside its limits",
        "names no joint",
        "unknown joint `wrist_joint`",
    ] {
        let answer: serde_json::Value =
            serde_json::from_str(&replies.recv().await.unwrap()).unwrap();
        assert_eq!(answer["t"], "refused", "{answer}");
        assert!(
            answer["reason"].as_str().unwrap().contains(says),
            "{answer}"
        );
    }
    assert!(recorder.joint_targets.borrow().is_empty());
    assert!(recorder
        .last_value("last_rejection")
        .unwrap()
        .starts_with("unknown joint `wrist_joint`"));
    assert_eq!(
        recorder.last_value("last_unreadable_sample").as_deref(),
        Some("joint_states: the sample ends early")
    );
}

#[tokio::test]
async fn a_save_runs_off_the_loop_and_every_browser_and_a_later_hello_hear_of_it() {
    let dir = std::env::temp_dir().join(format!("gui_bridge_bridge_save_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let arm = gui_bridge::load_arm("").unwrap();
    let panel = Panel::new(arm, 50.0, Desk::new(dir.clone()), "gui_bridge");
    let (senders, requests) = request_channels(&Limits::default());
    let (reply, _replies) = mpsc::channel(16);
    let save = ProgramOp::Save {
        name: "p".into(),
        overwrite: false,
    };
    for op in [ProgramOp::Teach, save] {
        let request = ClientRequest::Program(op);
        let reply = reply.clone();
        senders.try_send(FromClient { request, reply }).unwrap();
    }
    let (to_browsers, mut heard) = broadcast::channel::<String>(64);
    let (snapshot, view) = watch::channel(panel.snapshot());
    let saved = async move {
        while let Ok(text) = heard.recv().await {
            if text.contains("saved 1 points as p") {
                return;
            }
        }
    };
    let recorder = Recorder::default();
    let mut io = handles(futures::stream::pending(), requests, &recorder, saved);
    io.to_browsers = to_browsers;
    io.snapshot = snapshot;
    tokio::time::timeout(
        std::time::Duration::from_secs(10),
        gui_bridge::run(panel, io),
    )
    .await
    .expect("the save was never reported");
    assert!(dir.join("p.csv").is_file());
    let hello: serde_json::Value = serde_json::from_str(&view.borrow().hello(50.0)).unwrap();
    assert_eq!(hello["program"]["message"], "saved 1 points as p");
    assert_eq!(hello["program"]["files"], serde_json::json!(["p"]));
    let _ = std::fs::remove_dir_all(&dir);
}
