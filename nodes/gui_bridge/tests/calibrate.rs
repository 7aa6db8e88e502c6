//! The calibration wizard ([`gui_bridge::calibrate::Wizard`]) through its public API, on
//! a clock the test hands in (nothing waits) and a simulated arm that echoes every
//! `servo_angles` as `servo_state`.
#![allow(clippy::unwrap_used, clippy::expect_used)]
use eezybot_kinematics::calibration::{
    expected_gain, CALIBRATION_ORDER, COARSE_STEP_DEG, FINE_STEP_DEG,
};
use eezybot_kinematics::{ArmConfig, ServoCalibrations, ServoId};
use gui_bridge::calibrate::{Arm, Effect, Op, SaveOutcome, Wizard, TEST_POSE};
use gui_bridge::message::CalibrationView;
use gui_bridge::SaveJob;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// Index of a servo in `servo_angles` order.
fn idx(servo: ServoId) -> usize {
    ServoId::ALL.iter().position(|s| *s == servo).unwrap()
}

/// A servo's true line on the simulated arm: servo_deg = offset + gain · input.
#[derive(Clone, Copy, Debug)]
struct Line {
    offset: f64,
    gain: f64,
}

impl Line {
    fn at(self, input: f64) -> f64 {
        self.offset + self.gain * input
    }
}

/// The modelled miscalibration of the main test, in `servo_angles` order: the base's
/// horn 7° off; the main arm 3° off; the forearm servo mounted mirrored (reversed) and
/// 2° off; the claw closing at 63° with 5 % less swing.
const MODEL: [Line; 4] = [
    Line {
        offset: 97.0,
        gain: -2.0,
    },
    Line {
        offset: 183.0,
        gain: -1.0,
    },
    Line {
        offset: 92.0,
        gain: -1.0,
    },
    Line {
        offset: 63.0,
        gain: 114.0,
    },
];

fn shipped() -> ArmConfig {
    ArmConfig::shipped().unwrap()
}

fn ok() -> SaveOutcome {
    SaveOutcome {
        written: Ok((
            "/tmp/arm.yaml".into(),
            Some("/tmp/arm.yaml.bak".to_string()),
        )),
        applied: vec!["/compute_ik".into(), "/serial_node".into()],
        failed: vec![],
    }
}

fn servo_angles(fx: &[Effect]) -> Vec<[f64; 4]> {
    fx.iter()
        .filter_map(|e| match e {
            Effect::ServoAngles(a) => Some(*a),
            _ => None,
        })
        .collect()
}

fn set_calibrating(fx: &[Effect]) -> Vec<bool> {
    fx.iter()
        .filter_map(|e| match e {
            Effect::SetCalibrating(on) => Some(*on),
            _ => None,
        })
        .collect()
}

fn save_job(fx: &[Effect]) -> Option<SaveJob> {
    fx.iter().find_map(|e| match e {
        Effect::Save(job) => Some((**job).clone()),
        _ => None,
    })
}

/// The wizard, the clock, and the simulated arm.
struct Sim {
    w: Wizard,
    now: Instant,
    /// the servos' configured ranges (deg), `servo_angles` order
    ranges: [(f64, f64); 4],
    /// the last angles commanded (or the first servo_state)
    last: [f64; 4],
    /// every `servo_angles` sent
    sent: Vec<[f64; 4]>,
    /// the arm echoes `servo_angles` as `servo_state`
    echo: bool,
    /// every `servo_angles` must change at most one servo
    one_at_a_time: bool,
}

impl Sim {
    fn new(config: ArmConfig, state: [f64; 4]) -> Sim {
        let ranges = ServoId::ALL.map(|s| {
            let c = config.servos.get(s);
            (c.min_deg, c.max_deg)
        });
        let mut w = Wizard::new(config).unwrap();
        let now = Instant::now();
        assert!(w.on_servo_state(state, now).is_empty(), "idle: nothing");
        Sim {
            w,
            now,
            ranges,
            last: state,
            sent: vec![],
            echo: true,
            one_at_a_time: true,
        }
    }

    fn tick(&mut self) {
        self.now += Duration::from_millis(20);
    }

    fn view(&self) -> CalibrationView {
        self.w.view()
    }

    fn phase(&self) -> String {
        self.view().phase
    }

    /// Play the effects on the arm: each `servo_angles` checked, then echoed (which may
    /// start the next move). All effects, the echoes' included.
    fn play(&mut self, fx: Vec<Effect>) -> Vec<Effect> {
        let mut all = vec![];
        let mut pending = fx;
        while !pending.is_empty() {
            let mut next = vec![];
            for e in pending {
                if let Effect::ServoAngles(a) = e {
                    for (i, (lo, hi)) in self.ranges.iter().enumerate() {
                        assert!(
                            (*lo..=*hi).contains(&a[i]),
                            "servo {i} commanded to {} outside {lo} … {hi}: {a:?}",
                            a[i]
                        );
                    }
                    let changed = (0..4)
                        .filter(|&i| (a[i] - self.last[i]).abs() > 1e-9)
                        .count();
                    if self.one_at_a_time {
                        assert!(
                            changed <= 1,
                            "more than one servo moved: {:?} -> {a:?}",
                            self.last
                        );
                    }
                    self.last = a;
                    self.sent.push(a);
                    if self.echo {
                        self.tick();
                        next.extend(self.w.on_servo_state(a, self.now));
                    }
                }
                all.push(e);
            }
            pending = next;
        }
        all
    }

    fn req(&mut self, op: Op) -> Result<Vec<Effect>, String> {
        self.tick();
        let fx = self.w.request(op, self.now)?;
        Ok(self.play(fx))
    }

    /// A request that must be refused: the reason, and the view is unchanged.
    fn refused(&mut self, op: Op) -> String {
        let before = self.view();
        let sent = self.sent.len();
        let why = self
            .req(op.clone())
            .expect_err(&format!("{op:?} should be refused"));
        assert!(!why.is_empty());
        assert_eq!(self.view(), before, "{op:?} refused but the view changed");
        assert_eq!(self.sent.len(), sent, "{op:?} refused but something moved");
        why
    }

    /// Start the follower and let compute_ik answer.
    fn start_follower(&mut self) -> Vec<Effect> {
        let fx = self.req(Op::Start(Arm::Follower)).unwrap();
        assert_eq!(set_calibrating(&fx), [true]);
        assert!(
            servo_angles(&fx).is_empty(),
            "nothing moves before compute_ik is silent"
        );
        assert_eq!(self.phase(), "starting");
        assert!(self.w.holds_compute_ik());
        self.tick();
        let fx = self.w.on_calibrating_set(true, Ok(()), self.now);
        self.play(fx)
    }

    /// Jog the active servo to `target` in coarse then fine steps.
    fn jog_to(&mut self, target: f64) {
        for _ in 0..200 {
            let cur = self.view().commanded_deg.unwrap();
            let d = target - cur;
            if d.abs() < 1e-9 {
                return;
            }
            let step = if d.abs() >= COARSE_STEP_DEG {
                COARSE_STEP_DEG
            } else {
                FINE_STEP_DEG
            };
            assert!(
                d.abs() >= FINE_STEP_DEG - 1e-9,
                "{target} is not a fine step from {cur}"
            );
            self.req(Op::Jog(step.copysign(d)))
                .unwrap_or_else(|e| panic!("jog from {cur} towards {target}: {e}"));
        }
        panic!("never got to {target}");
    }

    /// The active step's reference `r`'s input (B's alternative if used).
    fn reference_input(&self, r: usize) -> f64 {
        let v = self.view();
        let s = &v.steps[v.step];
        match (&s.alternative_b, r) {
            (Some(alt), 1) if s.use_alternative => alt.input,
            _ => s.references[r].input,
        }
    }

    /// Jog the active servo to where the model shows reference `r`, and mark it.
    fn mark_model(&mut self, model: &[Line; 4], r: usize) -> Result<Vec<Effect>, String> {
        let v = self.view();
        assert_eq!(v.phase, "jog");
        assert_eq!(v.reference, r);
        let servo = CALIBRATION_ORDER[v.step];
        let target = model[idx(servo)].at(self.reference_input(r));
        self.jog_to(target);
        self.req(Op::Mark)
    }

    /// Mark both references of every step on the model: in review at the end.
    fn calibrate(&mut self, model: &[Line; 4]) {
        for step in 0..4 {
            assert_eq!(self.view().step, step);
            self.mark_model(model, 0).unwrap();
            self.mark_model(model, 1).unwrap();
            let v = self.view();
            assert!(v.steps[step].derived.is_some(), "{:?}", v.steps[step]);
            assert_eq!(v.steps[step].error, None);
        }
        assert_eq!(self.phase(), "review");
    }
}

fn home_state() -> [f64; 4] {
    // away from every start angle, so that each step has moves
    [80.0, 100.0, 70.0, 90.0]
}

fn assert_matches_model(servos: &ServoCalibrations, model: &[Line; 4]) {
    for s in ServoId::ALL {
        let (c, m) = (servos.get(s), model[idx(s)]);
        assert!(
            (c.offset_deg - m.offset).abs() <= 0.26,
            "{s:?}: offset {} vs {}",
            c.offset_deg,
            m.offset
        );
        assert!(
            ((c.gain - m.gain) / m.gain).abs() <= 0.01,
            "{s:?}: gain {} vs {}",
            c.gain,
            m.gain
        );
    }
}

// ---------------------------------------------------------------- 1. the follower

#[test]
fn a_follower_run_on_a_miscalibrated_arm_derives_it_saves_and_tests() {
    let mut sim = Sim::new(shipped(), home_state());
    assert!(!sim.w.is_active() && !sim.w.holds_compute_ik());
    let fx = sim.start_follower();
    assert!(!servo_angles(&fx).is_empty(), "the base moves to its start");
    assert_eq!(sim.phase(), "jog");
    // the base starts at the shipped home angle
    assert_eq!(sim.last[0], 90.0);
    assert_eq!(sim.view().commanded_deg, Some(90.0));
    assert_eq!(sim.view().state_deg, Some(90.0));
    let before_steps = sim.sent.len();
    sim.calibrate(&MODEL);
    assert!(sim.sent.len() > before_steps);
    assert!(sim.w.holds_compute_ik(), "review: compute_ik still silent");
    // the holds: the shoulder step held the forearm at φ = −35° through its new line
    assert!(
        sim.sent
            .iter()
            .any(|a| (a[2] - MODEL[2].at(-35.0)).abs() < 1e-9),
        "the forearm was never held at φ = −35°: {:?}",
        sim.sent
    );
    // derived as modelled, shown in the view
    let v = sim.view();
    // (the panel reads the fields by name)
    let derived = |i: usize| serde_json::to_value(v.steps[i].derived.as_ref().unwrap()).unwrap();
    let base = derived(0);
    assert_eq!(base["direction"], "as shipped");
    let elbow = derived(1);
    assert_eq!(v.steps[1].servo, "elbow");
    assert_eq!(elbow["direction"], "reversed");

    let fx = sim.req(Op::Save).unwrap();
    let job = save_job(&fx).expect("a save");
    assert!(job.end_calibrating);
    assert_eq!(job.leader, None);
    assert_matches_model(&job.servos, &MODEL);
    // the claw's range becomes its closed … open
    assert!((job.servos.gripper.min_deg - 63.0).abs() < 0.26);
    assert!((job.servos.gripper.max_deg - 177.0).abs() < 0.26);
    assert_eq!(sim.phase(), "saving");
    assert!(sim.w.holds_compute_ik());

    sim.tick();
    let fx = sim.w.on_saved(ok(), sim.now);
    let target = fx
        .iter()
        .find_map(|e| match e {
            Effect::JointTarget(j) => Some(j.clone()),
            _ => None,
        })
        .expect("the test move");
    let want = sim.w.test_joints();
    assert_eq!(target.len(), 4);
    for (name, v) in &target {
        assert_eq!(*v, want[name.as_str()], "{name}");
    }
    // TEST_POSE: base 20°, main arm 70°, forearm φ −30°, claw 30 % of 0.6 rad
    let [b, s, phi, open] = TEST_POSE;
    let expect = [
        ("base_joint", b.to_radians()),
        ("shoulder_joint", s.to_radians()),
        ("elbow_joint", (phi - s).to_radians()),
        ("gripper_joint", open * 0.6),
    ];
    for (name, v) in expect {
        assert!(
            (want[name] - v).abs() < 1e-12,
            "{name}: {} vs {v}",
            want[name]
        );
    }
    assert_eq!(sim.phase(), "testing");
    assert!(!sim.w.holds_compute_ik(), "compute_ik takes the arm back");
    let v = sim.view();
    let test = v.test.as_ref().unwrap();
    assert!(!test.done);
    assert_eq!(
        v.saved.as_ref().unwrap().path.as_deref(),
        Some("/tmp/arm.yaml")
    );
    // not there yet: still testing
    let mut js: BTreeMap<String, f64> = target.iter().cloned().collect();
    js.insert("base_joint".into(), want["base_joint"] + 0.02);
    assert!(sim.w.on_joint_states(&js).is_empty());
    assert_eq!(sim.phase(), "testing");
    js.insert("base_joint".into(), want["base_joint"] + 0.001);
    assert!(!sim.w.on_joint_states(&js).is_empty());
    assert_eq!(sim.phase(), "done");
    assert!(sim.view().test.unwrap().done);
    // the test again, then finish
    let fx = sim.req(Op::Test).unwrap();
    assert!(fx.iter().any(|e| matches!(e, Effect::JointTarget(_))));
    sim.req(Op::Finish).unwrap();
    assert!(!sim.w.is_active());
    assert_eq!(sim.phase(), "idle");
}

/// After mark A, the wizard moves the servo to where B is expected with the shipped
/// gain: on an arm that matches the shipped calibration, B is where the servo went, and
/// on the modelled one (a 2° horn error, a mirrored forearm servo) B needs fewer jogs
/// than from mark A.
#[test]
fn after_mark_a_the_servo_moves_to_where_b_is_expected() {
    let shipped_lines = ServoId::ALL.map(|s| {
        let c = ServoCalibrations::default();
        let c = c.get(s);
        Line {
            offset: c.offset_deg,
            gain: c.gain,
        }
    });
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    for (step, &servo) in CALIBRATION_ORDER.iter().enumerate() {
        let a = shipped_lines[idx(servo)].at(sim.reference_input(0));
        sim.mark_model(&shipped_lines, 0).unwrap();
        let expected = a + expected_gain(servo) * (sim.reference_input(1) - sim.reference_input(0));
        assert_eq!(sim.phase(), "jog", "step {step}: in place for B");
        assert!(
            (sim.view().commanded_deg.unwrap() - expected).abs() < 1e-9,
            "step {step} ({servo:?}): B expected at {expected}, servo at {:?}",
            sim.view().commanded_deg
        );
        sim.mark_model(&shipped_lines, 1).unwrap();
    }
    assert_eq!(sim.phase(), "review");

    let jogs_to_b = |first_move: bool| {
        let mut sim = Sim::new(shipped(), home_state());
        sim.start_follower();
        let mut jogs = 0;
        for _ in 0..4 {
            let servo = CALIBRATION_ORDER[sim.view().step];
            let a = MODEL[idx(servo)].at(sim.reference_input(0));
            sim.mark_model(&MODEL, 0).unwrap();
            let from = if first_move {
                sim.view().commanded_deg.unwrap()
            } else {
                a
            };
            let target = MODEL[idx(servo)].at(sim.reference_input(1));
            let d = (target - from).abs();
            jogs += (d / COARSE_STEP_DEG).floor() as usize
                + ((d % COARSE_STEP_DEG) / FINE_STEP_DEG).round() as usize;
            sim.mark_model(&MODEL, 1).unwrap();
        }
        jogs
    };
    let (now, before) = (jogs_to_b(true), jogs_to_b(false));
    assert!(
        now < before,
        "jogs to B: {now} from the expected B, {before} from mark A"
    );
}

#[test]
fn a_failed_save_returns_to_the_review_and_keeps_compute_ik_silent() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.calibrate(&MODEL);
    sim.req(Op::Save).unwrap();
    sim.tick();
    let fx = sim.w.on_saved(
        SaveOutcome {
            written: Err("disk full".into()),
            applied: vec![],
            failed: vec![],
        },
        sim.now,
    );
    assert!(!fx.iter().any(|e| matches!(e, Effect::JointTarget(_))));
    let v = sim.view();
    assert_eq!(v.phase, "review");
    assert!(v.error.as_deref().unwrap().contains("disk full"), "{v:?}");
    assert!(sim.w.holds_compute_ik());
    // saving again works
    let fx = sim.req(Op::Save).unwrap();
    assert_matches_model(&save_job(&fx).unwrap().servos, &MODEL);
}

// ---------------------------------------------------------------- 2. refusals

#[test]
fn requests_out_of_place_are_refused_and_change_nothing() {
    let mut sim = Sim::new(shipped(), home_state());
    // before start
    assert!(sim.refused(Op::Jog(0.5)).contains("start"));
    sim.refused(Op::Mark);
    sim.refused(Op::Back);
    sim.refused(Op::Save);
    sim.refused(Op::Cancel);
    sim.refused(Op::Finish);
    sim.refused(Op::Test);
    sim.refused(Op::Alternative(true));

    // while starting: no jog, no second start
    let fx = sim.req(Op::Start(Arm::Follower)).unwrap();
    assert_eq!(set_calibrating(&fx), [true]);
    sim.refused(Op::Jog(0.5));
    assert!(sim.refused(Op::Start(Arm::Follower)).contains("under way"));
    assert!(sim.refused(Op::Start(Arm::Leader)).contains("under way"));
    sim.tick();
    let fx = sim.w.on_calibrating_set(true, Ok(()), sim.now);
    sim.play(fx);
    assert_eq!(sim.phase(), "jog");
    sim.refused(Op::Start(Arm::Follower));

    // save before review
    assert!(sim.refused(Op::Save).contains("save when"));
    // bad jogs
    assert!(sim.refused(Op::Jog(5.5)).contains("at most"));
    sim.refused(Op::Jog(-10.0));
    sim.refused(Op::Jog(f64::NAN));
    sim.refused(Op::Jog(f64::INFINITY));
    sim.refused(Op::Jog(0.0));

    // beyond the jog range: the base's first range is 90 ± 10
    let range = sim.view().jog.unwrap();
    assert_eq!((range.min_deg, range.max_deg), (80.0, 100.0));
    sim.jog_to(97.5);
    sim.req(Op::Jog(5.0)).unwrap();
    assert_eq!(
        sim.view().commanded_deg,
        Some(100.0),
        "clamped to the range"
    );
    assert_eq!(sim.last[0], 100.0);
    assert!(sim.refused(Op::Jog(0.5)).contains("end of its jog range"));
    sim.refused(Op::Jog(5.0));
    sim.req(Op::Jog(-0.5)).unwrap();
    assert_eq!(sim.view().commanded_deg, Some(99.5));

    // mark before the servo arrived
    sim.echo = false;
    sim.req(Op::Jog(-5.0)).unwrap();
    assert_eq!(sim.view().commanded_deg, Some(94.5));
    assert_eq!(sim.view().state_deg, Some(99.5));
    assert!(sim.refused(Op::Mark).contains("not arrived"));
    // it arrives (the view shows it, nothing else happens): the mark is taken
    sim.tick();
    assert_eq!(sim.w.on_servo_state(sim.last, sim.now), [Effect::View]);
    assert_eq!(sim.view().state_deg, Some(94.5));
    sim.echo = true;
    sim.req(Op::Mark).unwrap();
    assert_eq!(sim.view().steps[0].marks, [Some(94.5), None]);
    assert_eq!(sim.view().reference, 1);
}

#[test]
fn within_arrival_tolerance_a_mark_is_taken_at_the_commanded_angle() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.echo = false;
    sim.req(Op::Jog(5.0)).unwrap();
    // servo_state rounded to the link's ticks: 0.4° short
    sim.tick();
    sim.w.on_servo_state([94.6, 90.0, 90.0, 60.0], sim.now);
    sim.req(Op::Mark).unwrap();
    assert_eq!(sim.view().steps[0].marks[0], Some(95.0));
}

#[test]
fn the_follower_is_not_started_without_servo_state() {
    let mut w = Wizard::new(shipped()).unwrap();
    let now = Instant::now();
    let before = w.view();
    let why = w.request(Op::Start(Arm::Follower), now).unwrap_err();
    assert!(why.contains("servo_state"), "{why}");
    assert_eq!(w.view(), before);
    assert!(!w.is_active() && !w.holds_compute_ik());
    // the leader needs none
    let fx = w.request(Op::Start(Arm::Leader), now).unwrap();
    assert!(set_calibrating(&fx).is_empty());
}

/// `Wizard::request` promises "nothing changes" on a refusal; a follower start without
/// servo_state after a finished leader run resets the run before refusing.
#[test]
fn a_refused_follower_start_keeps_a_finished_leader_run() {
    let mut w = Wizard::new(shipped()).unwrap();
    let mut now = Instant::now();
    w.request(Op::Start(Arm::Leader), now).unwrap();
    leader_run(&mut w, &mut now);
    w.request(Op::Save, now).unwrap();
    w.on_saved(ok(), now);
    assert_eq!(w.view().phase, "done");
    let before = w.view();
    assert!(w.request(Op::Start(Arm::Follower), now).is_err());
    assert_eq!(w.view(), before);
}

// ---------------------------------------------------------------- 3. implausible marks

#[test]
fn implausible_marks_are_refused_with_the_reason_and_mark_a_is_kept() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    // base: A at its start, 90°
    sim.req(Op::Mark).unwrap();
    assert_eq!(sim.view().steps[0].marks, [Some(90.0), None]);
    // B jogged the wrong way (turns the base the other way round): the base cannot reverse
    let jog = sim.view().jog.unwrap();
    assert_eq!(
        jog.max_deg, 95.0,
        "a non-reversible servo: B's side plus the slack"
    );
    sim.jog_to(95.0);
    let fx = sim.req(Op::Mark).unwrap();
    assert!(fx.iter().any(|e| matches!(e, Effect::Log(..))));
    let v = sim.view();
    let err = v.steps[0].error.clone().unwrap();
    assert!(err.contains("opposite direction"), "{err}");
    assert_eq!(v.steps[0].marks, [Some(90.0), None], "mark A kept");
    assert_eq!((v.step, v.reference, v.phase.as_str()), (0, 1, "jog"));
    assert!(v.steps[0].derived.is_none());
    // a gain half the shipped one (a 1:1 gear?)
    sim.jog_to(45.0);
    sim.req(Op::Mark).unwrap();
    let v = sim.view();
    let err = v.steps[0].error.clone().unwrap();
    assert!(err.contains("gain") && err.contains("50 %"), "{err}");
    assert_eq!(v.steps[0].marks, [Some(90.0), None]);
    assert_eq!((v.step, v.reference), (0, 1));
    // marks too close
    sim.jog_to(88.0);
    sim.req(Op::Mark).unwrap();
    assert!(sim.view().steps[0]
        .error
        .clone()
        .unwrap()
        .contains("less than"));
    // the right one: derived, the error gone, on to the forearm
    sim.jog_to(0.0);
    sim.req(Op::Mark).unwrap();
    let v = sim.view();
    assert_eq!(v.steps[0].error, None);
    assert_eq!(v.steps[0].marks, [Some(90.0), Some(0.0)]);
    let d = serde_json::to_value(v.steps[0].derived.as_ref().unwrap()).unwrap();
    assert_eq!(
        (d["offset_deg"].as_f64(), d["gain"].as_f64()),
        (Some(90.0), Some(-2.0))
    );
    assert_eq!(v.step, 1);
    assert_eq!(v.steps[1].servo, "elbow");
}

// ---------------------------------------------------------------- 4. back, alternative

#[test]
fn back_undoes_the_marks_and_the_later_steps() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    assert!(sim.refused(Op::Back).contains("nothing marked"));
    // base A, back: A gone
    sim.mark_model(&MODEL, 0).unwrap();
    assert_eq!(sim.view().reference, 1);
    sim.req(Op::Back).unwrap();
    let v = sim.view();
    assert_eq!((v.step, v.reference), (0, 0));
    assert_eq!(v.steps[0].marks, [None, None]);
    // base and forearm done, main arm's A marked
    sim.mark_model(&MODEL, 0).unwrap();
    sim.mark_model(&MODEL, 1).unwrap();
    sim.mark_model(&MODEL, 0).unwrap();
    sim.mark_model(&MODEL, 1).unwrap();
    sim.mark_model(&MODEL, 0).unwrap();
    let v = sim.view();
    assert_eq!((v.step, v.reference), (2, 1));
    assert!(v.steps[1].derived.is_some());
    // back: the main arm's A
    sim.req(Op::Back).unwrap();
    let v = sim.view();
    assert_eq!((v.step, v.reference), (2, 0));
    assert_eq!(v.steps[2].marks, [None, None]);
    assert!(v.steps[1].derived.is_some(), "the forearm stays derived");
    // back again: the forearm's B, its derivation gone, A kept
    sim.req(Op::Back).unwrap();
    let v = sim.view();
    assert_eq!((v.step, v.reference), (1, 1));
    assert!(v.steps[1].derived.is_none());
    assert_eq!(v.steps[1].marks[1], None);
    assert_eq!(v.steps[1].marks[0], Some(MODEL[2].at(0.0)));
    assert!(v.steps[0].derived.is_some());
    assert_eq!(v.steps[0].marks[1], Some(MODEL[0].at(45.0)));
    // and on again to the review; back from the review reopens the claw's B
    sim.mark_model(&MODEL, 1).unwrap();
    assert_eq!(sim.view().step, 2);
    sim.mark_model(&MODEL, 0).unwrap();
    sim.mark_model(&MODEL, 1).unwrap();
    sim.mark_model(&MODEL, 0).unwrap();
    sim.mark_model(&MODEL, 1).unwrap();
    assert_eq!(sim.phase(), "review");
    sim.req(Op::Back).unwrap();
    let v = sim.view();
    assert_eq!((v.phase.as_str(), v.step, v.reference), ("jog", 3, 1));
    assert!(v.steps[3].derived.is_none());
    sim.refused(Op::Save);
    sim.mark_model(&MODEL, 1).unwrap();
    let fx = sim.req(Op::Save).unwrap();
    assert_matches_model(&save_job(&fx).unwrap().servos, &MODEL);
}

#[test]
fn back_past_a_derived_step_forgets_every_later_step() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.mark_model(&MODEL, 0).unwrap();
    sim.mark_model(&MODEL, 1).unwrap();
    // forearm: nothing marked; back reopens the base's B
    assert_eq!(sim.view().step, 1);
    sim.req(Op::Back).unwrap();
    let v = sim.view();
    assert_eq!((v.step, v.reference), (0, 1));
    assert!(v.steps.iter().all(|s| s.derived.is_none()));
    assert_eq!(v.steps[0].marks, [Some(MODEL[0].at(0.0)), None]);
}

#[test]
fn the_base_may_be_marked_at_its_alternative_b() {
    // a base whose horn sits 7° the other way: 45° left would need −7°, out of reach;
    // 45° right is at 173°
    let mut model = MODEL;
    model[0].offset = 83.0;
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    let v = sim.view();
    let alt = v.steps[0].alternative_b.as_ref().unwrap();
    assert_eq!(alt.input, -45.0);
    assert!(!v.steps[0].use_alternative);
    sim.mark_model(&model, 0).unwrap();
    // B (45° left) lies below 0°
    assert!(model[0].at(45.0) < 0.0);
    sim.req(Op::Alternative(true)).unwrap();
    let v = sim.view();
    assert!(v.steps[0].use_alternative);
    // the servo went to where the alternative is expected: mark A, 90° of base further
    // at the shipped gain (−2), inside the jog range
    let expected =
        (83.0 + expected_gain(ServoId::Base) * -45.0).min(v.jog.as_ref().unwrap().max_deg);
    assert_eq!(v.commanded_deg, Some(expected));
    assert!(v.instruction.contains("right"), "{}", v.instruction);
    let jog = v.jog.unwrap();
    assert!(
        (jog.min_deg..=jog.max_deg).contains(&model[0].at(-45.0)),
        "{jog:?}"
    );
    sim.mark_model(&model, 1).unwrap();
    let v = sim.view();
    assert_eq!(v.steps[0].marks, [Some(83.0), Some(173.0)]);
    let d = serde_json::to_value(v.steps[0].derived.as_ref().unwrap()).unwrap();
    assert_eq!(d["offset_deg"].as_f64(), Some(83.0));
    assert_eq!(d["gain"].as_f64(), Some(-2.0));
    // the forearm has no alternative
    assert_eq!(v.step, 1);
    assert!(v.steps[1].alternative_b.is_none());
    assert!(sim
        .refused(Op::Alternative(true))
        .contains("no alternative"));
    // the rest, and the save uses the base's alternative derivation
    sim.mark_model(&model, 0).unwrap();
    sim.mark_model(&model, 1).unwrap();
    for _ in 2..4 {
        sim.mark_model(&model, 0).unwrap();
        sim.mark_model(&model, 1).unwrap();
    }
    let fx = sim.req(Op::Save).unwrap();
    assert_matches_model(&save_job(&fx).unwrap().servos, &model);
}

// ---------------------------------------------------------------- 5. e-stop

#[test]
fn the_estop_pauses_a_queued_move_and_refuses_jogs_until_released() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.mark_model(&MODEL, 0).unwrap();
    // B marked: the forearm step's moves start; the arm holds the first one back
    sim.echo = false;
    let base_b = MODEL[0].at(45.0);
    sim.jog_to(base_b);
    // (without echo jog_to would not wait: let the base arrive by hand)
    sim.tick();
    sim.w.on_servo_state(sim.last, sim.now);
    let fx = sim.req(Op::Mark).unwrap();
    let first = servo_angles(&fx);
    assert_eq!(first.len(), 1, "one move at a time: {fx:?}");
    assert_eq!(sim.phase(), "moving");
    // the e-stop: the move waits
    sim.tick();
    let fx = sim.w.on_estop(true, sim.now);
    assert!(servo_angles(&fx).is_empty());
    assert!(
        sim.view().instruction.contains("E-stop"),
        "{}",
        sim.view().instruction
    );
    sim.echo = true;
    // the arm reports (it holds wherever it is): nothing is sent while engaged
    for _ in 0..3 {
        sim.tick();
        let fx = sim.w.on_servo_state(sim.last, sim.now);
        assert!(servo_angles(&fx).is_empty(), "{fx:?}");
        sim.tick();
        assert!(sim.w.on_tick(sim.now + Duration::from_secs(600)).is_empty());
    }
    assert!(sim.refused(Op::Jog(0.5)).contains("moving"));
    // released: the move goes on and the step's moves run to the end
    sim.tick();
    let fx = sim.w.on_estop(false, sim.now);
    assert!(!servo_angles(&fx).is_empty(), "resumed: {fx:?}");
    sim.play(fx);
    assert_eq!(sim.phase(), "jog");
    assert_eq!(sim.view().step, 1);
    // engaged while jogging: jogs refused, then taken after the release
    sim.tick();
    sim.w.on_estop(true, sim.now);
    assert!(sim.refused(Op::Jog(0.5)).contains("emergency stop"));
    sim.tick();
    sim.w.on_estop(false, sim.now);
    sim.req(Op::Jog(0.5)).unwrap();
}

#[test]
fn an_estop_before_compute_ik_answers_holds_the_first_move() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.req(Op::Start(Arm::Follower)).unwrap();
    sim.tick();
    sim.w.on_estop(true, sim.now);
    sim.tick();
    let fx = sim.w.on_calibrating_set(true, Ok(()), sim.now);
    assert!(servo_angles(&fx).is_empty(), "{fx:?}");
    assert_eq!(sim.phase(), "moving");
    sim.tick();
    let fx = sim.w.on_estop(false, sim.now);
    assert_eq!(servo_angles(&fx).len(), 1);
    sim.play(fx);
    assert_eq!(sim.phase(), "jog");
    assert_eq!(sim.last[0], 90.0);
}

// ---------------------------------------------------------------- 6. a stalled move

#[test]
fn a_move_that_never_arrives_fails_after_its_deadline_and_releases_compute_ik() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.echo = false;
    let fx = sim.start_follower();
    assert_eq!(servo_angles(&fx).len(), 1);
    assert_eq!(sim.phase(), "moving");
    // well within the deadline: nothing
    assert!(sim
        .w
        .on_tick(sim.now + Duration::from_millis(500))
        .is_empty());
    assert_eq!(sim.phase(), "moving");
    // the servo reports, but elsewhere (stalled)
    let fx = sim.w.on_servo_state([85.0, 100.0, 70.0, 90.0], sim.now);
    assert!(fx.is_empty());
    let fx = sim.w.on_tick(sim.now + Duration::from_secs(120));
    assert_eq!(set_calibrating(&fx), [false]);
    let v = sim.view();
    assert_eq!(v.phase, "failed");
    let err = v.error.unwrap();
    assert!(err.contains("Base") && err.contains("85.0"), "{err}");
    assert!(!sim.w.holds_compute_ik());
    // nothing more happens; finish, or start again
    assert!(sim.w.on_tick(sim.now + Duration::from_secs(240)).is_empty());
    sim.refused(Op::Jog(0.5));
    sim.req(Op::Finish).unwrap();
    assert!(!sim.w.is_active());
}

#[test]
fn compute_ik_refusing_to_go_silent_fails_without_moving() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.req(Op::Start(Arm::Follower)).unwrap();
    sim.tick();
    let fx = sim
        .w
        .on_calibrating_set(true, Err("no such parameter".into()), sim.now);
    assert!(servo_angles(&fx).is_empty());
    assert!(set_calibrating(&fx).is_empty(), "it was never set");
    assert_eq!(sim.phase(), "failed");
    assert!(sim.view().error.unwrap().contains("no such parameter"));
    assert!(!sim.w.holds_compute_ik());
    // start again
    sim.start_follower();
    assert_eq!(sim.phase(), "jog");
}

// ---------------------------------------------------------------- 7. cancel

#[test]
fn cancel_releases_compute_ik_for_the_follower() {
    // while starting, moving, jogging and in review
    for stop_at in ["starting", "moving", "jog", "review"] {
        let mut sim = Sim::new(shipped(), home_state());
        if stop_at == "starting" {
            sim.req(Op::Start(Arm::Follower)).unwrap();
        } else {
            sim.echo = stop_at != "moving";
            sim.start_follower();
            if stop_at == "review" {
                sim.calibrate(&MODEL);
            }
        }
        assert_eq!(sim.phase(), stop_at);
        assert!(sim.w.holds_compute_ik(), "{stop_at}");
        let sent = sim.sent.len();
        let fx = sim.req(Op::Cancel).unwrap();
        assert_eq!(set_calibrating(&fx), [false], "{stop_at}");
        assert!(!sim.w.holds_compute_ik());
        assert!(!sim.w.is_active());
        assert_eq!(sim.phase(), "idle");
        // a move under way is forgotten
        sim.tick();
        let fx = sim.w.on_servo_state(sim.last, sim.now);
        assert!(servo_angles(&fx).is_empty());
        assert!(sim.w.on_tick(sim.now + Duration::from_secs(600)).is_empty());
        assert_eq!(sim.sent.len(), sent);
        // nothing more to cancel
        sim.refused(Op::Cancel);
    }
}

#[test]
fn holds_compute_ik_only_while_the_follower_runs() {
    let mut sim = Sim::new(shipped(), home_state());
    assert!(!sim.w.holds_compute_ik());
    sim.req(Op::Start(Arm::Follower)).unwrap();
    assert!(sim.w.holds_compute_ik());
    sim.tick();
    let fx = sim.w.on_calibrating_set(true, Ok(()), sim.now);
    sim.play(fx);
    assert!(sim.w.holds_compute_ik());
    sim.calibrate(&MODEL);
    sim.req(Op::Save).unwrap();
    assert!(sim.w.holds_compute_ik(), "saving");
    sim.tick();
    sim.w.on_saved(ok(), sim.now);
    assert!(
        !sim.w.holds_compute_ik(),
        "testing: compute_ik drives again"
    );
    // leader: never
    let mut w = Wizard::new(shipped()).unwrap();
    w.request(Op::Start(Arm::Leader), sim.now).unwrap();
    assert!(w.is_active() && !w.holds_compute_ik());
    let fx = w.request(Op::Cancel, sim.now).unwrap();
    assert!(set_calibrating(&fx).is_empty());
}

// ---------------------------------------------------------------- 8. the leader

/// Leader counts at each step's references A and B, channel by channel (A0 … A3 =
/// base, shoulder, elbow, gripper): 4, 3, 3 counts per degree and 400 per opening.
fn leader_counts(step: usize, r: usize) -> [f64; 4] {
    let table: [[f64; 2]; 4] = [
        [512.0, 692.0], // base: 0°, 45° left
        [500.0, 365.0], // forearm: φ 0°, −45°
        [400.0, 265.0], // main arm: 90°, 45°
        [300.0, 700.0], // claw: closed, open
    ];
    let mut c = [111.0, 222.0, 333.0, 444.0];
    c[idx(CALIBRATION_ORDER[step])] = table[step][r];
    c
}

/// Mark every reference of a leader run: in review at the end.
fn leader_run(w: &mut Wizard, now: &mut Instant) {
    for step in 0..4 {
        for r in 0..2 {
            *now += Duration::from_millis(50);
            let v = w.view();
            assert_eq!((v.phase.as_str(), v.step, v.reference), ("jog", step, r));
            let fx = w.request(Op::Mark, *now).unwrap();
            assert!(servo_angles(&fx).is_empty());
            assert_eq!(w.view().phase, "reading");
            *now += Duration::from_millis(50);
            let fx = w.on_leader_counts(leader_counts(step, r), *now);
            assert!(servo_angles(&fx).is_empty());
        }
    }
    assert_eq!(w.view().phase, "review");
}

#[test]
fn a_leader_run_marks_counts_of_each_steps_channel_and_saves_a_leader_section() {
    let mut w = Wizard::new(shipped()).unwrap();
    let mut now = Instant::now();
    let fx = w.request(Op::Start(Arm::Leader), now).unwrap();
    assert!(set_calibrating(&fx).is_empty());
    assert!(servo_angles(&fx).is_empty());
    let v = w.view();
    assert_eq!(
        (v.arm.as_str(), v.phase.as_str(), v.step),
        ("leader", "jog", 0)
    );
    assert!(v.jog.is_none() && v.commanded_deg.is_none());
    assert!(v.instruction.contains("by hand"), "{}", v.instruction);
    assert!(w
        .request(Op::Jog(0.5), now)
        .unwrap_err()
        .contains("by hand"));
    // counts before a mark are shown, not marked
    let fx = w.on_leader_counts([1.0, 2.0, 3.0, 4.0], now);
    assert!(fx.contains(&Effect::View));
    assert_eq!(w.view().counts, Some([1.0, 2.0, 3.0, 4.0]));
    assert_eq!(w.view().steps[0].marks, [None, None]);
    // a mark takes the next counts of the step's channel
    w.request(Op::Mark, now).unwrap();
    assert!(w.request(Op::Mark, now).unwrap_err().contains("reading"));
    w.on_leader_counts(leader_counts(0, 0), now);
    assert_eq!(w.view().steps[0].marks, [Some(512.0), None]);
    // back while reading: no mark taken
    w.request(Op::Mark, now).unwrap();
    w.request(Op::Back, now).unwrap();
    assert_eq!(w.view().phase, "jog");
    w.on_leader_counts(leader_counts(0, 1), now);
    assert_eq!(w.view().steps[0].marks, [Some(512.0), None]);
    // back again: A undone; the whole run
    w.request(Op::Back, now).unwrap();
    leader_run(&mut w, &mut now);
    let v = w.view();
    for (step, s) in v.steps.iter().enumerate() {
        assert_eq!(s.channel, idx(CALIBRATION_ORDER[step]));
        assert_eq!(
            s.marks,
            [
                Some(leader_counts(step, 0)[s.channel]),
                Some(leader_counts(step, 1)[s.channel])
            ],
            "{}",
            s.servo
        );
        assert!(s.derived.is_some());
    }
    let fx = w.request(Op::Save, now).unwrap();
    let job = save_job(&fx).unwrap();
    assert!(!job.end_calibrating);
    assert_eq!(job.servos, shipped().servos, "the servos untouched");
    let leader = job.leader.unwrap();
    let base = leader.base.unwrap();
    assert_eq!(
        (base.counts_a, base.input_a, base.counts_b, base.input_b),
        (512.0, 0.0, 692.0, 45.0)
    );
    let elbow = leader.elbow.unwrap();
    assert_eq!((elbow.counts_a, elbow.counts_b), (500.0, 365.0));
    assert_eq!((elbow.input_a, elbow.input_b), (0.0, -45.0));
    let shoulder = leader.shoulder.unwrap();
    assert_eq!(
        (
            shoulder.counts_a,
            shoulder.input_a,
            shoulder.counts_b,
            shoulder.input_b
        ),
        (400.0, 90.0, 265.0, 45.0)
    );
    let gripper = leader.gripper.unwrap();
    assert_eq!((gripper.counts_a, gripper.counts_b), (300.0, 700.0));
    assert_eq!(leader.adc_max, 1023);
    let fx = w.on_saved(ok(), now);
    assert!(!fx.iter().any(|e| matches!(e, Effect::JointTarget(_))));
    assert_eq!(w.view().phase, "done");
    assert!(w.view().test.is_none());
    assert!(w.request(Op::Test, now).is_err());
    w.request(Op::Finish, now).unwrap();
    assert!(!w.is_active());
}

#[test]
fn a_leader_reading_at_a_rail_is_refused() {
    let mut w = Wizard::new(shipped()).unwrap();
    let now = Instant::now();
    w.request(Op::Start(Arm::Leader), now).unwrap();
    w.request(Op::Mark, now).unwrap();
    w.on_leader_counts([512.0, 0.0, 0.0, 0.0], now);
    w.request(Op::Mark, now).unwrap();
    // the base's wiper at its end stop
    w.on_leader_counts([1020.0, 0.0, 0.0, 0.0], now);
    let v = w.view();
    let err = v.steps[0].error.clone().unwrap();
    assert!(err.contains("rail"), "{err}");
    assert_eq!(v.steps[0].marks, [Some(512.0), None]);
    assert_eq!((v.phase.as_str(), v.step, v.reference), ("jog", 0, 1));
    w.request(Op::Mark, now).unwrap();
    w.on_leader_counts([692.0, 0.0, 0.0, 0.0], now);
    let v = w.view();
    assert_eq!(v.steps[0].error, None);
    assert_eq!(v.step, 1);
}

// ---------------------------------------------------------------- 9. the servo ranges

#[test]
fn every_command_stays_inside_the_servos_configured_ranges() {
    // servo_state rounded just below the claw's 60° minimum
    let state = [80.0, 100.0, 70.0, 59.98];
    let mut sim = Sim::new(shipped(), state);
    // the first command clamps the claw into its range as it moves the base
    sim.one_at_a_time = false;
    sim.start_follower();
    assert_eq!(sim.sent[0][3], 60.0);
    sim.one_at_a_time = true;
    sim.calibrate(&MODEL);
    assert!(!sim.sent.is_empty());
    // (each command was checked against the ranges in Sim::play)

    // a narrower configured range: the base may only turn within 85 … 175°
    let mut config = shipped();
    config.servos.base.min_deg = 85.0;
    config.servos.base.max_deg = 175.0;
    let mut sim = Sim::new(config, [80.0, 90.0, 90.0, 60.0]);
    sim.one_at_a_time = false;
    sim.start_follower();
    let jog = sim.view().jog.unwrap();
    assert_eq!((jog.min_deg, jog.max_deg), (85.0, 100.0));
    sim.jog_to(85.0);
    assert!(sim.refused(Op::Jog(-0.5)).contains("end of its jog range"));
    assert!(sim.sent.iter().all(|a| (85.0..=175.0).contains(&a[0])));
}

// ---------------------------------------------------------------- 10. the view

#[test]
fn the_view_serializes_with_the_fields_the_page_reads_and_right_poses() {
    let mut sim = Sim::new(shipped(), home_state());
    let idle = serde_json::to_value(sim.view()).unwrap();
    assert_eq!(idle["active"], false);
    assert_eq!(idle["phase"], "idle");
    assert!(idle["jog"].is_null());
    sim.start_follower();
    let v = serde_json::to_value(sim.view()).unwrap();
    assert_eq!(v["active"], true);
    assert_eq!(v["phase"], "jog");
    assert_eq!(v["step"], 0);
    assert_eq!(v["arm"], "follower");
    assert!(v["instruction"].as_str().unwrap().contains("Base"), "{v}");
    assert_eq!(v["jog"]["min_deg"], 80.0);
    assert_eq!(v["jog"]["max_deg"], 100.0);
    assert_eq!(v["jog"]["fine_deg"], FINE_STEP_DEG);
    assert_eq!(v["jog"]["coarse_deg"], COARSE_STEP_DEG);
    assert_eq!(v["commanded_deg"], 90.0);
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 4);
    let names: Vec<&str> = steps.iter().map(|s| s["servo"].as_str().unwrap()).collect();
    assert_eq!(names, ["base", "elbow", "shoulder", "gripper"]);
    for s in steps {
        let refs = s["references"].as_array().unwrap();
        assert_eq!(refs.len(), 2);
        for r in refs {
            for joint in [
                "base_joint",
                "shoulder_joint",
                "elbow_joint",
                "gripper_joint",
            ] {
                assert!(r["pose"][joint].is_f64(), "{joint} in {r}");
            }
            assert!(r["description"].is_string());
        }
    }
    let pose = |step: usize, r: usize, joint: &str| {
        steps[step]["references"][r]["pose"][joint]
            .as_f64()
            .unwrap()
    };
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    // base 45° left, the rest at home
    assert!(close(pose(0, 1, "base_joint"), 45f64.to_radians()));
    assert!(close(pose(0, 1, "shoulder_joint"), 90f64.to_radians()));
    assert!(close(pose(0, 1, "elbow_joint"), (-90f64).to_radians()));
    assert!(close(
        steps[0]["alternative_b"]["pose"]["base_joint"]
            .as_f64()
            .unwrap(),
        (-45f64).to_radians()
    ));
    // forearm horizontal, then 45° down, with the main arm vertical
    assert!(close(pose(1, 0, "elbow_joint"), (-90f64).to_radians()));
    assert!(close(pose(1, 1, "shoulder_joint"), 90f64.to_radians()));
    assert!(close(pose(1, 1, "elbow_joint"), (-135f64).to_radians()));
    // main arm vertical and 45° forward, the forearm held at φ −35°
    assert!(close(
        pose(2, 0, "elbow_joint"),
        (-35f64 - 90.0).to_radians()
    ));
    assert!(close(pose(2, 1, "shoulder_joint"), 45f64.to_radians()));
    assert!(close(
        pose(2, 1, "elbow_joint"),
        (-35f64 - 45.0).to_radians()
    ));
    // claw closed and open
    assert!(close(pose(3, 0, "gripper_joint"), 0.0));
    assert!(close(pose(3, 1, "gripper_joint"), 0.6));
    assert_eq!(v["gripper_open_rad"], 0.6);
    // the test description after saving
    sim.calibrate(&MODEL);
    sim.req(Op::Save).unwrap();
    sim.w.on_saved(ok(), sim.now);
    let v = serde_json::to_value(sim.view()).unwrap();
    assert_eq!(v["phase"], "testing");
    assert_eq!(v["saved"]["path"], "/tmp/arm.yaml");
    assert_eq!(v["saved"]["backup"], "/tmp/arm.yaml.bak");
    assert_eq!(v["test"]["done"], false);
    assert!(
        (v["test"]["pose"]["elbow_joint"].as_f64().unwrap() - (-100f64).to_radians()).abs() < 1e-12
    );
    let d = v["test"]["description"].as_str().unwrap();
    assert!(d.contains("20° left") && d.contains("30 % open"), "{d}");
}

#[test]
fn a_new_config_applies_only_while_no_wizard_runs() {
    let mut narrow = shipped();
    narrow.servos.base.min_deg = 85.0;
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.w.set_config(narrow.clone()).unwrap();
    assert_eq!(
        sim.view().jog.unwrap().min_deg,
        80.0,
        "ignored while active"
    );
    sim.req(Op::Cancel).unwrap();
    sim.w.set_config(narrow).unwrap();
    sim.start_follower();
    assert_eq!(sim.view().jog.unwrap().min_deg, 85.0);
}

#[test]
fn a_test_move_that_never_arrives_ends_with_an_error() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.calibrate(&MODEL);
    sim.req(Op::Save).unwrap();
    sim.w.on_saved(ok(), sim.now);
    assert_eq!(sim.phase(), "testing");
    assert!(sim.w.on_tick(sim.now + Duration::from_secs(1)).is_empty());
    assert_eq!(sim.phase(), "testing");
    assert!(!sim.w.on_tick(sim.now + Duration::from_secs(60)).is_empty());
    let v = sim.view();
    assert_eq!(v.phase, "done");
    assert!(v.error.unwrap().contains("joint_states"));
    assert!(!v.test.unwrap().done);
}

/// A cancel while the save runs is refused (the file may be half applied); a save
/// outcome that comes when none is awaited starts no test move.
#[test]
fn a_cancel_waits_for_the_save_and_a_stray_save_moves_nothing() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.calibrate(&MODEL);
    sim.req(Op::Save).unwrap();
    let why = sim.req(Op::Cancel).unwrap_err();
    assert!(why.contains("saving"), "{why}");
    assert_eq!(sim.phase(), "saving");
    let fx = sim.w.on_saved(ok(), sim.now);
    assert!(fx.iter().any(|e| matches!(e, Effect::JointTarget(_))));
    sim.req(Op::Finish).unwrap();
    // a second outcome, not awaited
    let fx = sim.w.on_saved(ok(), sim.now);
    assert!(
        !fx.iter().any(|e| matches!(e, Effect::JointTarget(_))),
        "{fx:?}"
    );
    assert!(!sim.w.is_active(), "{}", sim.phase());
}

/// Back from the main arm's step to the forearm's B leaves the main arm wherever it was
/// jogged, not at the forearm step's hold (main arm vertical).
#[test]
fn back_into_an_earlier_step_poses_its_holds_again() {
    let mut sim = Sim::new(shipped(), home_state());
    sim.start_follower();
    sim.mark_model(&MODEL, 0).unwrap();
    sim.mark_model(&MODEL, 1).unwrap();
    sim.mark_model(&MODEL, 0).unwrap();
    sim.mark_model(&MODEL, 1).unwrap();
    // the main arm's step: jogged 10° before marking anything, then back
    assert_eq!(sim.view().step, 2);
    sim.jog_to(80.0);
    sim.req(Op::Back).unwrap();
    let v = sim.view();
    assert_eq!((v.step, v.reference), (1, 1));
    // the forearm's hold: the main arm's servo at the shipped home angle, 90°
    assert_eq!(sim.last[idx(ServoId::Shoulder)], 90.0, "{:?}", sim.last);
}

/// A leader mark with no leader reader running does not wait for ever: after
/// `READING_TIMEOUT` the wizard says why and lets the user mark again.
#[test]
fn a_leader_mark_without_counts_gives_up_and_says_why() {
    let t0 = Instant::now();
    let mut w = Wizard::new(shipped()).unwrap();
    w.request(Op::Start(Arm::Leader), t0).unwrap();
    w.request(Op::Mark, t0).unwrap();
    assert_eq!(w.view().phase, "reading");
    assert!(w.on_tick(t0 + Duration::from_secs(2)).is_empty());
    let later = t0 + gui_bridge::calibrate::READING_TIMEOUT + Duration::from_millis(100);
    assert_eq!(w.on_tick(later), [Effect::View]);
    let v = w.view();
    assert_eq!(v.phase, "jog");
    assert!(
        v.error.as_deref().unwrap_or("").contains("leader_counts"),
        "{v:?}"
    );
    assert_eq!(v.steps[0].marks, [None, None]);
    // the reader starts: the next mark takes its counts
    w.request(Op::Mark, later).unwrap();
    w.on_leader_counts([512.0, 452.0, 600.0, 300.0], later);
    assert_eq!(w.view().steps[0].marks, [Some(512.0), None]);
}
