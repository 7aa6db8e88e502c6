//! The calibration wizard (issue 22) as a state machine without I/O: requests of the
//! panel or the command line in, [`Effect`]s out, on a clock the caller gives.
//!
//! **The follower** (the arm's own servos): compute_ik is told to send nothing
//! ([`Effect::SetCalibrating`]); the wizard then drives the servos itself on
//! `servo_angles`, one servo at a time (a move starts when the previous one arrived on
//! `servo_state`), through serial_node's velocity guard and e-stop. For each servo in
//! [`CALIBRATION_ORDER`] it poses the joints [`calibration::Hold`] names, moves the servo
//! to its start angle, and lets the user jog it (fine or coarse, inside the step's jog
//! range and the servo's configured range) until the arm shows reference A, then B, and
//! mark each. Two marks give the servo's calibration ([`calibration::derive`]), or a
//! refusal with the reason. Once all four are derived, [`Effect::Save`] writes the file
//! and applies it live; compute_ik takes the arm back where `servo_state` says it is, and
//! the wizard sends a guided test move ([`TEST_POSE`]).
//!
//! **The leader** (a leader arm's potentiometers, serial_node `role:=leader`): the user
//! moves the leader by hand to the same references and marks each; the marks are the
//! ADC counts of the next `leader_counts` report ([`calibration::derive_leader`]).
//! Nothing moves and compute_ik is not involved.

use crate::message::{CalibrationView, DerivedView, DirectionView, SavedView, StepView, TestView};
use eezybot_kinematics::calibration::{
    self, derive, derive_leader, CalibrationError, CalibrationPlan, Direction, JogRange,
    LeaderReading, Mark, Reference, ServoPlan, Tolerances, CALIBRATION_ORDER, COARSE_STEP_DEG,
    FINE_STEP_DEG,
};
use eezybot_kinematics::{
    ArmConfig, LeaderCalibration, LeaderChannel, ServoCalibration, ServoCalibrations, ServoId,
};
use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

/// A servo has arrived when `servo_state` is within this of its command (servo deg).
pub const ARRIVED_DEG: f64 = 0.6;
/// How long a move may take beyond what the servo's velocity limit needs.
pub const MOVE_SLACK: Duration = Duration::from_secs(3);
/// The guided test move after saving: joint inputs (base_joint, shoulder_joint, forearm
/// elevation φ in deg; claw opening), inside the shipped limits, away from every
/// reference so that a wrong offset or gain shows.
pub const TEST_POSE: [f64; 4] = [20.0, 70.0, -30.0, 0.3];
/// The test move has arrived when every `joint_states` joint is within this (rad).
pub const TEST_ARRIVED_RAD: f64 = 0.005;
/// How long the test move may take.
pub const TEST_TIMEOUT: Duration = Duration::from_secs(15);
/// How long a leader mark waits for the next `leader_counts` report.
pub const READING_TIMEOUT: Duration = Duration::from_secs(3);
/// The view is sent again when the active servo's `servo_state` moved this far since
/// the last view (deg), or arrived.
pub const STATE_VIEW_DEG: f64 = 1.0;

/// Which arm is calibrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arm {
    /// The servos this graph drives.
    Follower,
    /// A leader arm's potentiometers.
    Leader,
}

impl Arm {
    /// `follower` or `leader`.
    pub fn name(self) -> &'static str {
        match self {
            Arm::Follower => "follower",
            Arm::Leader => "leader",
        }
    }

    /// From its name.
    pub fn parse(s: &str) -> Option<Arm> {
        match s {
            "follower" => Some(Arm::Follower),
            "leader" => Some(Arm::Leader),
            _ => None,
        }
    }
}

/// What the user asks of the wizard.
#[derive(Clone, Debug, PartialEq)]
pub enum Op {
    /// Begin calibrating this arm.
    Start(Arm),
    /// Move the active servo by this many servo degrees.
    Jog(f64),
    /// Mark the current reference.
    Mark,
    /// Undo the last mark.
    Back,
    /// Use reference B's alternative (or not).
    Alternative(bool),
    /// Save, apply, then test.
    Save,
    /// Repeat the test move.
    Test,
    /// Leave without saving.
    Cancel,
    /// Leave after saving.
    Finish,
}

/// What the caller must do.
#[derive(Clone, Debug, PartialEq)]
pub enum Effect {
    /// Take the arm from compute_ik (or give it back), then call [`Wizard::on_calibrating_set`].
    SetCalibrating(bool),
    /// Publish `servo_angles` at these horn angles (deg, `servo_angles` order).
    ServoAngles([f64; 4]),
    /// Write this calibration (the servos and the leader section) atomically, set
    /// `arm_config` to the file on compute_ik and every serial_node (the caller fills
    /// in [`crate::SaveJob::nodes`]), and for the follower set compute_ik's
    /// the arm back after that; then call [`Wizard::on_saved`].
    Save(Box<crate::SaveJob>),
    /// Publish `joint_target` with these joints (rad).
    JointTarget(Vec<(String, f64)>),
    /// The view changed: tell every browser (or print it).
    View,
    /// Log this.
    Log(log::Level, String),
}

/// The outcome of [`Effect::Save`].
#[derive(Clone, Debug, PartialEq)]
pub struct SaveOutcome {
    /// The file written, or why not.
    pub written: Result<(String, Option<String>), String>,
    /// Nodes whose `arm_config` was set.
    pub applied: Vec<String>,
    /// Nodes that refused it, with why.
    pub failed: Vec<String>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Idle,
    /// waiting for compute_ik to hand over the arm
    Starting,
    /// moving servos one at a time (the queue)
    Moving,
    /// the user jogs and marks
    Jog,
    /// a leader mark waits for the next counts
    Reading,
    /// every servo derived
    Review,
    /// waiting for the save
    Saving,
    /// saved; the test move runs
    Testing,
    /// saved (and tested)
    Done,
    /// ended by an error; start again
    Failed,
}

impl Phase {
    fn name(self) -> &'static str {
        match self {
            Phase::Idle => "idle",
            Phase::Starting => "starting",
            Phase::Moving => "moving",
            Phase::Jog => "jog",
            Phase::Reading => "reading",
            Phase::Review => "review",
            Phase::Saving => "saving",
            Phase::Testing => "testing",
            Phase::Done => "done",
            Phase::Failed => "failed",
        }
    }
}

/// What a step derived.
#[derive(Clone, Debug, PartialEq)]
enum Derivation {
    Servo(calibration::Derived),
    Leader(LeaderChannel),
}

/// A move of one servo the wizard waits for.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Move {
    servo: ServoId,
    deg: f64,
}

/// The wizard. See the [module](self) documentation.
#[derive(Debug)]
pub struct Wizard {
    config: ArmConfig,
    plan: CalibrationPlan,
    tolerances: Tolerances,
    arm: Arm,
    phase: Phase,
    /// index into [`CALIBRATION_ORDER`]
    step: usize,
    /// the reference to mark next (0 = A, 1 = B)
    reference: usize,
    use_alternative: [bool; 4],
    /// per step: the marks (servo deg, or counts)
    marks: [[Option<f64>; 2]; 4],
    derived: [Option<Derivation>; 4],
    step_error: [Option<String>; 4],
    /// the servo angles the wizard commands (deg, `servo_angles` order)
    commanded: Option<[f64; 4]>,
    queue: VecDeque<Move>,
    /// the move under way and when it must have arrived
    moving: Option<(Move, Instant)>,
    /// latest `servo_state` (deg)
    state: Option<[f64; 4]>,
    /// latest leader counts
    counts: Option<[f64; 4]>,
    estop: bool,
    error: Option<String>,
    saved: Option<SaveOutcome>,
    test_started: Option<Instant>,
    test_done: bool,
    /// when a leader mark started waiting for counts
    reading_since: Option<Instant>,
    /// the active servo's `servo_state` and arrival as last shown
    shown_state: Option<(f64, bool)>,
}

/// Servo-degree velocity limits of the configuration, for how long a move may take.
fn move_time(config: &ArmConfig, servo: ServoId, deg: f64) -> Duration {
    let v = servo
        .of([
            &config.motion.base,
            &config.motion.shoulder,
            &config.motion.elbow,
            &config.motion.gripper,
        ])
        .max_velocity_deg_s
        .max(1.0);
    Duration::from_secs_f64((deg.abs() / v).min(60.0)) + MOVE_SLACK
}

fn index(servo: ServoId) -> usize {
    servo.of([0, 1, 2, 3])
}

fn show_input(servo: ServoId, input: f64) -> String {
    match servo {
        ServoId::Gripper => format!("{input:.2}"),
        _ => format!("{input:.1}°"),
    }
}

fn title(servo: ServoId) -> &'static str {
    servo.of(["Base", "Main arm", "Forearm", "Claw"])
}

impl Wizard {
    /// A wizard for an arm with `config` (its limits, and the calibration it replaces).
    pub fn new(config: ArmConfig) -> Result<Wizard, CalibrationError> {
        let plan = CalibrationPlan::new(&config)?;
        Ok(Wizard {
            config,
            plan,
            tolerances: Tolerances::default(),
            arm: Arm::Follower,
            phase: Phase::Idle,
            step: 0,
            reference: 0,
            use_alternative: [false; 4],
            marks: [[None; 2]; 4],
            derived: [None, None, None, None],
            step_error: [None, None, None, None],
            commanded: None,
            queue: VecDeque::new(),
            moving: None,
            state: None,
            counts: None,
            estop: false,
            error: None,
            saved: None,
            test_started: None,
            test_done: false,
            reading_since: None,
            shown_state: None,
        })
    }

    /// Replace the configuration (a new `arm_config` was loaded) while no wizard runs.
    pub fn set_config(&mut self, config: ArmConfig) -> Result<(), CalibrationError> {
        if self.is_active() {
            return Ok(());
        }
        self.plan = CalibrationPlan::new(&config)?;
        self.config = config;
        Ok(())
    }

    /// Whether `servo_state` was heard (a follower's calibration starts from it).
    pub fn has_servo_state(&self) -> bool {
        self.state.is_some()
    }

    /// Whether a calibration is under way (compute_ik may be silent).
    pub fn is_active(&self) -> bool {
        !matches!(self.phase, Phase::Idle)
    }

    /// Saving: the file being written and applied (it gives the arm back itself).
    pub fn saving(&self) -> bool {
        self.phase == Phase::Saving
    }

    /// Whether the wizard holds the arm (taken from compute_ik, not yet given back): the
    /// caller must give it back when it shuts down now.
    pub fn holds_compute_ik(&self) -> bool {
        self.arm == Arm::Follower
            && matches!(
                self.phase,
                Phase::Starting | Phase::Moving | Phase::Jog | Phase::Review | Phase::Saving
            )
    }

    fn servo(&self) -> ServoId {
        CALIBRATION_ORDER[self.step]
    }

    fn step_plan(&self) -> &ServoPlan {
        self.plan.get(self.servo())
    }

    /// The reference the step's mark `r` is for (B or its alternative).
    fn reference_of(&self, step: usize, r: usize) -> Reference {
        let plan = self.plan.get(CALIBRATION_ORDER[step]);
        match (r, plan.alternative_b) {
            (1, Some(alt)) if self.use_alternative[step] => alt,
            _ => plan.references[r],
        }
    }

    /// Handle a request at `now`: the effects, or why it is refused (nothing changes).
    pub fn request(&mut self, op: Op, now: Instant) -> Result<Vec<Effect>, String> {
        let mut fx = vec![];
        match op {
            Op::Start(arm) => {
                if !matches!(self.phase, Phase::Idle | Phase::Done | Phase::Failed) {
                    return Err("a calibration is under way: cancel it first".into());
                }
                if arm == Arm::Follower && self.state.is_none() {
                    return Err("no servo_state heard: is serial_node running with the arm?".into());
                }
                self.reset(arm);
                match arm {
                    Arm::Follower => {
                        self.phase = Phase::Starting;
                        fx.push(Effect::SetCalibrating(true));
                        fx.push(Effect::Log(
                            log::Level::Info,
                            "calibration of the follower started: compute_ik told to send nothing"
                                .into(),
                        ));
                    }
                    Arm::Leader => {
                        self.phase = Phase::Jog;
                        fx.push(Effect::Log(
                            log::Level::Info,
                            "calibration of the leader arm started".into(),
                        ));
                    }
                }
            }
            Op::Jog(deg) => {
                self.expect_jog()?;
                if self.arm == Arm::Leader {
                    return Err("the leader arm is moved by hand: nothing to jog".into());
                }
                if !deg.is_finite() || deg.abs() > COARSE_STEP_DEG + 1e-9 || deg == 0.0 {
                    return Err(format!(
                        "a jog is a step of at most {COARSE_STEP_DEG}° (got {deg})"
                    ));
                }
                if self.estop {
                    return Err("the emergency stop is engaged: release it to jog".into());
                }
                let range = self.jog_range().ok_or("no jog range")?;
                let servo = self.servo();
                let cmd = self.commanded.ok_or("no servo commanded yet")?;
                let now_deg = cmd[index(servo)];
                let next = range.clamp(now_deg + deg);
                if (next - now_deg).abs() < 1e-9 {
                    return Err(format!(
                        "{} is at the end of its jog range {:.1}° … {:.1}°",
                        title(servo),
                        range.min_deg,
                        range.max_deg
                    ));
                }
                self.command(servo, next, &mut fx);
            }
            Op::Mark => {
                self.expect_jog()?;
                match self.arm {
                    Arm::Follower => {
                        let servo = self.servo();
                        let cmd = self.commanded.ok_or("no servo commanded yet")?;
                        let deg = cmd[index(servo)];
                        let arrived = self
                            .state
                            .map(|s| (s[index(servo)] - deg).abs() <= ARRIVED_DEG)
                            .unwrap_or(false);
                        if !arrived {
                            return Err(format!(
                                "{} has not arrived at {deg:.1}° yet (servo_state: {}): mark when it has",
                                title(servo),
                                self.state
                                    .map(|s| format!("{:.1}°", s[index(servo)]))
                                    .unwrap_or_else(|| "none".into())
                            ));
                        }
                        self.record_mark(deg, now, &mut fx);
                    }
                    Arm::Leader => {
                        self.phase = Phase::Reading;
                        self.reading_since = Some(now);
                    }
                }
            }
            Op::Back => {
                if !matches!(self.phase, Phase::Jog | Phase::Review | Phase::Reading) {
                    return Err(format!("nothing to undo while {}", self.phase.name()));
                }
                if self.phase == Phase::Reading {
                    self.phase = Phase::Jog;
                } else if self.phase == Phase::Review {
                    self.step = 3;
                    self.reference = 1;
                    self.marks[3][1] = None;
                    self.derived[3] = None;
                    self.phase = Phase::Jog;
                } else if self.reference == 1 {
                    self.reference = 0;
                    self.marks[self.step][0] = None;
                    self.step_error[self.step] = None;
                } else if self.step > 0 {
                    self.step -= 1;
                    self.reference = 1;
                    self.marks[self.step][1] = None;
                    self.derived[self.step] = None;
                    self.step_error[self.step] = None;
                    // later steps' holds depended on this one: forget them too
                    for s in self.step + 1..4 {
                        self.marks[s] = [None; 2];
                        self.derived[s] = None;
                        self.step_error[s] = None;
                    }
                    // the later step may have moved this step's held joints
                    if self.arm == Arm::Follower {
                        self.queue_holds();
                        if !self.queue.is_empty() {
                            self.phase = Phase::Moving;
                            self.next_move(now, &mut fx);
                        }
                    }
                } else {
                    return Err("nothing marked yet".into());
                }
                self.error = None;
            }
            Op::Alternative(on) => {
                self.expect_jog()?;
                if self.step_plan().alternative_b.is_none() {
                    return Err(format!(
                        "{} has no alternative reference",
                        title(self.servo())
                    ));
                }
                let changed = self.use_alternative[self.step] != on;
                self.use_alternative[self.step] = on;
                if let (true, Arm::Follower, 1, Some(a)) =
                    (changed, self.arm, self.reference, self.marks[self.step][0])
                {
                    // B moved: so does the servo, to where the new B is expected
                    self.move_to_expected_b(a, now, &mut fx);
                }
            }
            Op::Save => {
                if self.phase != Phase::Review {
                    return Err("save when every servo is marked and derived".into());
                }
                let (servos, leader) = self.result()?;
                self.phase = Phase::Saving;
                fx.push(Effect::Save(Box::new(crate::SaveJob {
                    servos,
                    leader,
                    end_calibrating: self.arm == Arm::Follower,
                    nodes: vec![],
                })));
            }
            Op::Test => {
                if self.arm != Arm::Follower || !matches!(self.phase, Phase::Done | Phase::Testing)
                {
                    return Err(
                        "the test move comes after saving the follower's calibration".into(),
                    );
                }
                self.start_test(now, &mut fx);
            }
            Op::Cancel => {
                if self.phase == Phase::Idle {
                    return Err("no calibration to cancel".into());
                }
                if self.phase == Phase::Saving {
                    return Err("saving: wait until it is written and applied".into());
                }
                if self.holds_compute_ik() {
                    fx.push(Effect::SetCalibrating(false));
                }
                fx.push(Effect::Log(
                    log::Level::Info,
                    "calibration cancelled: nothing saved".into(),
                ));
                self.phase = Phase::Idle;
                self.queue.clear();
                self.moving = None;
            }
            Op::Finish => {
                if !matches!(self.phase, Phase::Done | Phase::Testing | Phase::Failed) {
                    return Err("finish after saving (or cancel)".into());
                }
                self.phase = Phase::Idle;
            }
        }
        self.error = None;
        fx.push(Effect::View);
        Ok(fx)
    }

    /// A request was refused: keep the reason for the view.
    pub fn refused(&mut self, reason: &str) -> Vec<Effect> {
        self.error = Some(reason.to_string());
        vec![Effect::View]
    }

    fn expect_jog(&self) -> Result<(), String> {
        match self.phase {
            Phase::Jog => Ok(()),
            Phase::Moving => Err("wait: a servo is moving to its next pose".into()),
            Phase::Reading => Err("wait: reading the leader".into()),
            Phase::Idle => Err("start a calibration first".into()),
            p => Err(format!("not while {}", p.name())),
        }
    }

    fn reset(&mut self, arm: Arm) {
        self.arm = arm;
        self.step = 0;
        self.reference = 0;
        self.use_alternative = [false; 4];
        self.marks = [[None; 2]; 4];
        self.derived = [None, None, None, None];
        self.step_error = [None, None, None, None];
        self.queue.clear();
        self.moving = None;
        self.error = None;
        self.saved = None;
        self.test_started = None;
        self.test_done = false;
        self.commanded = None;
    }

    /// compute_ik handed over the arm, or took it back (or refused).
    pub fn on_calibrating_set(
        &mut self,
        on: bool,
        result: Result<(), String>,
        now: Instant,
    ) -> Vec<Effect> {
        let mut fx = vec![];
        match (on, result) {
            (true, Ok(())) if self.phase == Phase::Starting => {
                let Some(state) = self.state else {
                    return self.fail("no servo_state: is serial_node running?", true);
                };
                // the servos stay where they are; the first step poses its joints
                self.commanded = Some(state);
                self.enter_step(now, &mut fx);
            }
            (true, Err(e)) if self.phase == Phase::Starting => {
                return self.fail(
                    &format!("compute_ik could not be told to send nothing ({e}): nothing moved"),
                    false,
                );
            }
            (false, Err(e)) => fx.push(Effect::Log(
                log::Level::Error,
                format!("the arm could not be given back to compute_ik ({e}): give it back by hand, `ros2 control switch_controllers --deactivate calibration`"),
            )),
            _ => {}
        }
        fx.push(Effect::View);
        fx
    }

    fn fail(&mut self, why: &str, release: bool) -> Vec<Effect> {
        self.phase = Phase::Failed;
        self.error = Some(why.to_string());
        self.queue.clear();
        self.moving = None;
        let mut fx = vec![Effect::Log(log::Level::Warn, format!("calibration: {why}"))];
        if release && self.arm == Arm::Follower {
            fx.push(Effect::SetCalibrating(false));
        }
        fx.push(Effect::View);
        fx
    }

    /// Queue the moves that pose the step's holds and put its servo at its start.
    fn enter_step(&mut self, now: Instant, fx: &mut Vec<Effect>) {
        self.reference = 0;
        if self.arm == Arm::Leader {
            self.phase = Phase::Jog;
            return;
        }
        self.queue_holds();
        let plan = self.step_plan();
        let start = self.first_range().clamp(plan.start_deg());
        self.queue.push_back(Move {
            servo: plan.servo,
            deg: start,
        });
        self.phase = Phase::Moving;
        self.next_move(now, fx);
    }

    /// Queue the moves that pose the active step's held joints.
    fn queue_holds(&mut self) {
        let plan = self.step_plan().clone();
        for h in &plan.holds {
            let deg = if h.calibrated_first {
                match &self.derived[CALIBRATION_ORDER
                    .iter()
                    .position(|s| *s == h.servo)
                    .unwrap_or(0)]
                {
                    Some(Derivation::Servo(d)) => {
                        d.calibration.offset_deg + d.calibration.gain * h.input
                    }
                    _ => continue,
                }
            } else {
                let c = ServoCalibrations::default();
                let c = c.get(h.servo);
                c.offset_deg + c.gain * h.input
            };
            self.queue.push_back(Move {
                servo: h.servo,
                deg: self.allowed(h.servo).clamp(deg),
            });
        }
    }

    /// The servo's configured range (serial_node refuses angles outside it).
    fn allowed(&self, servo: ServoId) -> JogRange {
        let c = self.config.servos.get(servo);
        JogRange {
            min_deg: c.min_deg.max(0.0),
            max_deg: c.max_deg.min(180.0),
        }
    }

    fn first_range(&self) -> JogRange {
        intersect(
            self.step_plan().first_jog_range(),
            self.allowed(self.servo()),
        )
    }

    /// Where the active servo may be jogged now.
    pub fn jog_range(&self) -> Option<JogRange> {
        if self.arm == Arm::Leader || !self.is_active() {
            return None;
        }
        let plan = self.step_plan();
        let range = match (self.reference, self.marks[self.step][0]) {
            (1, Some(a)) => {
                let b = self.reference_of(self.step, 1).input;
                let shipped = plan.second_jog_range(a, b, Direction::AsShipped, &self.tolerances);
                if calibration::is_reversible(plan.servo) {
                    // which way this servo turns its joint shows only with mark B
                    let reversed =
                        plan.second_jog_range(a, b, Direction::Reversed, &self.tolerances);
                    JogRange {
                        min_deg: shipped.min_deg.min(reversed.min_deg),
                        max_deg: shipped.max_deg.max(reversed.max_deg),
                    }
                } else {
                    shipped
                }
            }
            _ => plan.first_jog_range(),
        };
        Some(intersect(range, self.allowed(plan.servo)))
    }

    fn command(&mut self, servo: ServoId, deg: f64, fx: &mut Vec<Effect>) {
        let mut cmd = self.commanded.unwrap_or([90.0; 4]);
        cmd[index(servo)] = deg;
        // servo_state's angles are rounded to the link's ticks: one taken as the
        // command may lie a hair outside the configured range, which serial_node refuses
        for s in ServoId::ALL {
            cmd[index(s)] = self.allowed(s).clamp(cmd[index(s)]);
        }
        self.commanded = Some(cmd);
        fx.push(Effect::ServoAngles(cmd));
    }

    fn next_move(&mut self, now: Instant, fx: &mut Vec<Effect>) {
        if self.estop {
            return;
        }
        while let Some(m) = self.queue.pop_front() {
            let from = self.commanded.map(|c| c[index(m.servo)]).unwrap_or(m.deg);
            if (from - m.deg).abs() < 1e-6 && self.arrived(m) {
                continue;
            }
            self.command(m.servo, m.deg, fx);
            self.moving = Some((m, now + move_time(&self.config, m.servo, from - m.deg)));
            return;
        }
        self.moving = None;
        if self.phase == Phase::Moving {
            self.phase = Phase::Jog;
        }
    }

    fn arrived(&self, m: Move) -> bool {
        self.state
            .map(|s| (s[index(m.servo)] - m.deg).abs() <= ARRIVED_DEG)
            .unwrap_or(false)
    }

    fn record_mark(&mut self, value: f64, now: Instant, fx: &mut Vec<Effect>) {
        let step = self.step;
        self.marks[step][self.reference] = Some(value);
        self.step_error[step] = None;
        if self.reference == 0 {
            self.reference = 1;
            self.phase = Phase::Jog;
            if self.arm == Arm::Follower {
                self.move_to_expected_b(value, now, fx);
            }
            return;
        }
        let servo = self.servo();
        let (a, b) = (self.reference_of(step, 0), self.reference_of(step, 1));
        let [Some(ma), Some(mb)] = self.marks[step] else {
            return;
        };
        let result = match self.arm {
            Arm::Follower => derive(
                &self.config,
                servo,
                [Mark::new(a.input, ma), Mark::new(b.input, mb)],
                self.config.servos.get(servo),
                &self.tolerances,
            )
            .map(Derivation::Servo),
            Arm::Leader => derive_leader(
                &self.config,
                servo,
                [
                    LeaderReading {
                        input: a.input,
                        counts: ma,
                    },
                    LeaderReading {
                        input: b.input,
                        counts: mb,
                    },
                ],
                self.adc_max(),
                &self.tolerances,
            )
            .map(Derivation::Leader),
        };
        match result {
            Ok(d) => {
                fx.push(Effect::Log(
                    log::Level::Info,
                    format!("calibration: {} derived: {}", title(servo), describe(&d)),
                ));
                self.derived[step] = Some(d);
                if step == 3 {
                    self.phase = Phase::Review;
                } else {
                    self.step += 1;
                    self.enter_step(now, fx);
                }
            }
            Err(e) => {
                // keep mark A: the user marks B again, or goes back
                self.marks[step][1] = None;
                self.phase = Phase::Jog;
                let why = e.to_string();
                fx.push(Effect::Log(
                    log::Level::Warn,
                    format!("calibration: {} refused: {why}", title(servo)),
                ));
                self.step_error[step] = Some(why);
            }
        }
    }

    /// After mark A (`mark_a_deg`): the servo moves to where reference B is expected,
    /// mark A plus the shipped gain times the inputs' difference (in the shipped
    /// direction; within the jog range), so B takes a few fine jogs.
    fn move_to_expected_b(&mut self, mark_a_deg: f64, now: Instant, fx: &mut Vec<Effect>) {
        let servo = self.servo();
        let (a, b) = (
            self.reference_of(self.step, 0),
            self.reference_of(self.step, 1),
        );
        let expected = mark_a_deg + calibration::expected_gain(servo) * (b.input - a.input);
        let Some(range) = self.jog_range() else {
            return;
        };
        self.queue.push_back(Move {
            servo,
            deg: range.clamp(expected),
        });
        self.phase = Phase::Moving;
        self.next_move(now, fx);
    }

    fn adc_max(&self) -> u16 {
        self.config
            .leader
            .as_ref()
            .map(|l| l.adc_max)
            .unwrap_or(calibration::DEFAULT_ADC_MAX)
    }

    /// The calibration to save.
    fn result(&self) -> Result<(ServoCalibrations, Option<LeaderCalibration>), String> {
        let mut servos = self.config.servos;
        let mut leader = self.config.leader;
        for (i, servo) in CALIBRATION_ORDER.iter().enumerate() {
            match &self.derived[i] {
                Some(Derivation::Servo(d)) => set_servo(&mut servos, *servo, d.calibration),
                Some(Derivation::Leader(c)) => leader
                    .get_or_insert_with(|| LeaderCalibration {
                        adc_max: self.adc_max(),
                        ..LeaderCalibration::default()
                    })
                    .set(*servo, *c),
                None => return Err(format!("{} is not derived yet", title(*servo))),
            }
        }
        Ok((servos, leader))
    }

    /// The file was written and applied (or not).
    pub fn on_saved(&mut self, outcome: SaveOutcome, now: Instant) -> Vec<Effect> {
        let mut fx = vec![];
        if self.phase != Phase::Saving {
            // not asked for now (cannot happen: cancel waits for a save); nothing moves
            return vec![Effect::Log(
                log::Level::Warn,
                "calibration: a save finished while none was awaited: ignored".into(),
            )];
        }
        let ok = outcome.written.is_ok();
        match &outcome.written {
            Ok((path, _)) => fx.push(Effect::Log(
                log::Level::Info,
                format!(
                    "calibration saved to {path}; applied to {}{}",
                    if outcome.applied.is_empty() {
                        "no node".to_string()
                    } else {
                        outcome.applied.join(", ")
                    },
                    if outcome.failed.is_empty() {
                        String::new()
                    } else {
                        format!("; not applied: {}", outcome.failed.join("; "))
                    }
                ),
            )),
            Err(e) => fx.push(Effect::Log(
                log::Level::Error,
                format!("calibration not saved: {e}"),
            )),
        }
        self.saved = Some(outcome);
        if !ok {
            // back to the review: the user may try again, or cancel
            self.phase = Phase::Review;
            self.error = self
                .saved
                .as_ref()
                .and_then(|s| s.written.clone().err())
                .map(|e| format!("not saved: {e}"));
            fx.push(Effect::View);
            return fx;
        }
        // the new calibration is this wizard's configuration from now on
        if let Ok((servos, leader)) = self.result() {
            self.config.servos = servos;
            self.config.leader = leader;
        }
        if self.arm == Arm::Follower {
            self.start_test(now, &mut fx);
        } else {
            self.phase = Phase::Done;
        }
        fx.push(Effect::View);
        fx
    }

    fn start_test(&mut self, now: Instant, fx: &mut Vec<Effect>) {
        self.phase = Phase::Testing;
        self.test_started = Some(now);
        self.test_done = false;
        fx.push(Effect::JointTarget(
            self.test_joints()
                .into_iter()
                .map(|(n, v)| (n.to_string(), v))
                .collect(),
        ));
    }

    /// The test pose's joints (rad).
    pub fn test_joints(&self) -> BTreeMap<&'static str, f64> {
        pose_joints(&self.config, TEST_POSE)
    }

    /// `servo_state` (deg, `servo_angles` order) came.
    pub fn on_servo_state(&mut self, deg: [f64; 4], now: Instant) -> Vec<Effect> {
        self.state = Some(deg);
        let mut fx = vec![];
        if let Some((m, _)) = self.moving {
            if self.arrived(m) {
                self.next_move(now, &mut fx);
                fx.push(Effect::View);
                return fx;
            }
        }
        if self.phase == Phase::Jog && self.arm == Arm::Follower {
            // the page (and the terminal) see the servo arrive where it was jogged
            let i = index(self.servo());
            let arrived = self
                .commanded
                .is_some_and(|c| (deg[i] - c[i]).abs() <= ARRIVED_DEG);
            let changed = match self.shown_state {
                Some((shown, was)) => was != arrived || (deg[i] - shown).abs() >= STATE_VIEW_DEG,
                None => true,
            };
            if changed {
                self.shown_state = Some((deg[i], arrived));
                fx.push(Effect::View);
            }
        }
        fx
    }

    /// The leader's counts (A0 … A3) came.
    pub fn on_leader_counts(&mut self, counts: [f64; 4], now: Instant) -> Vec<Effect> {
        self.counts = Some(counts);
        let mut fx = vec![];
        if self.arm == Arm::Leader && self.phase == Phase::Reading {
            self.reading_since = None;
            let c = counts[index(self.servo())];
            self.record_mark(c, now, &mut fx);
        }
        if self.arm == Arm::Leader && self.is_active() {
            fx.push(Effect::View);
        }
        fx
    }

    /// `estop` as heard.
    pub fn on_estop(&mut self, engaged: bool, now: Instant) -> Vec<Effect> {
        let was = self.estop;
        self.estop = engaged;
        let mut fx = vec![];
        if was && !engaged && self.phase == Phase::Moving && self.moving.is_none() {
            self.next_move(now, &mut fx);
        }
        if was != engaged && self.is_active() {
            if engaged {
                // serial_node holds the servos; the move under way waits for the release
                if let Some((m, _)) = self.moving.take() {
                    self.queue.push_front(m);
                }
            }
            fx.push(Effect::View);
        }
        fx
    }

    /// `joint_states` (rad by joint name) came: the test move's progress.
    pub fn on_joint_states(&mut self, joints: &BTreeMap<String, f64>) -> Vec<Effect> {
        if self.phase != Phase::Testing || self.test_done {
            return vec![];
        }
        let arrived = self.test_joints().iter().all(|(name, want)| {
            joints
                .get(*name)
                .map(|q| (q - want).abs() <= TEST_ARRIVED_RAD)
                .unwrap_or(false)
        });
        if arrived {
            self.test_done = true;
            self.phase = Phase::Done;
            return vec![
                Effect::Log(
                    log::Level::Info,
                    "calibration: the test move arrived; compare the arm with the picture".into(),
                ),
                Effect::View,
            ];
        }
        vec![]
    }

    /// Time passed: a move that did not arrive in time, a test move that did not.
    pub fn on_tick(&mut self, now: Instant) -> Vec<Effect> {
        if self.estop {
            return vec![];
        }
        if let Some((m, deadline)) = self.moving {
            if now > deadline {
                let got = self
                    .state
                    .map(|s| format!("{:.1}°", s[index(m.servo)]))
                    .unwrap_or_else(|| "nothing".into());
                return self.fail(
                    &format!(
                        "{} did not reach {:.1}° (servo_state says {got}): is it stalled or unpowered?",
                        title(m.servo),
                        m.deg
                    ),
                    true,
                );
            }
        }
        if self.phase == Phase::Reading {
            if let Some(t) = self.reading_since {
                if now.duration_since(t) > READING_TIMEOUT {
                    self.phase = Phase::Jog;
                    self.reading_since = None;
                    self.error = Some(format!(
                        "no leader_counts heard for {:.0} s: is the leader's serial_node (role:=leader) running?",
                        READING_TIMEOUT.as_secs_f64()
                    ));
                    return vec![Effect::View];
                }
            }
        }
        if self.phase == Phase::Testing && !self.test_done {
            if let Some(t) = self.test_started {
                if now.duration_since(t) > TEST_TIMEOUT {
                    self.phase = Phase::Done;
                    self.error = Some(
                        "the test move did not arrive on joint_states: see compute_ik's diagnostics"
                            .into(),
                    );
                    return vec![Effect::View];
                }
            }
        }
        vec![]
    }

    /// What the panel shows.
    pub fn view(&self) -> CalibrationView {
        let open = self.config.geometry.gripper_open_rad;
        let steps = CALIBRATION_ORDER
            .iter()
            .enumerate()
            .map(|(i, &servo)| {
                let plan = self.plan.get(servo);
                let pose = |r: Reference| pose_joints(&self.config, self.pose_inputs(i, r.input));
                let reference_view = |r: Reference| crate::message::ReferenceView {
                    input: r.input,
                    description: r.description.to_string(),
                    pose: pose(r),
                };
                StepView {
                    servo: servo.name().trim_end_matches("_servo").to_string(),
                    title: title(servo).to_string(),
                    channel: index(servo),
                    input_name: calibration::input_name(servo).to_string(),
                    unit: if servo == ServoId::Gripper {
                        "opening"
                    } else {
                        "deg"
                    }
                    .to_string(),
                    references: [
                        reference_view(plan.references[0]),
                        reference_view(plan.references[1]),
                    ],
                    alternative_b: plan.alternative_b.map(reference_view),
                    use_alternative: self.use_alternative[i],
                    holds: plan
                        .holds
                        .iter()
                        .map(|h| h.description.to_string())
                        .collect(),
                    marks: self.marks[i],
                    derived: self.derived[i].as_ref().map(|d| match d {
                        Derivation::Servo(d) => DerivedView::Servo {
                            offset_deg: d.calibration.offset_deg,
                            gain: d.calibration.gain,
                            direction: match d.direction {
                                Direction::AsShipped => DirectionView::AsShipped,
                                Direction::Reversed => DirectionView::Reversed,
                            },
                            gain_ratio: d.gain_ratio,
                            min_deg: d.calibration.min_deg,
                            max_deg: d.calibration.max_deg,
                        },
                        Derivation::Leader(c) => DerivedView::Leader {
                            counts_a: c.counts_a,
                            input_a: c.input_a,
                            counts_b: c.counts_b,
                            input_b: c.input_b,
                        },
                    }),
                    error: self.step_error[i].clone(),
                }
            })
            .collect();
        let active = self.is_active();
        let servo = self.servo();
        let follower = self.arm == Arm::Follower && active;
        CalibrationView {
            active,
            arm: self.arm.name().to_string(),
            phase: self.phase.name().to_string(),
            step: self.step,
            steps,
            reference: self.reference,
            commanded_deg: self
                .commanded
                .filter(|_| follower)
                .map(|c| c[index(servo)]),
            state_deg: self.state.filter(|_| follower).map(|s| s[index(servo)]),
            jog: self.jog_range().map(|r| crate::message::JogView {
                min_deg: r.min_deg,
                max_deg: r.max_deg,
                fine_deg: FINE_STEP_DEG,
                coarse_deg: COARSE_STEP_DEG,
            }),
            counts: self.counts.filter(|_| self.arm == Arm::Leader),
            instruction: self.instruction(),
            error: self.error.clone(),
            saved: self.saved.as_ref().map(|s| SavedView {
                path: s.written.as_ref().ok().map(|(p, _)| p.clone()),
                backup: s.written.as_ref().ok().and_then(|(_, b)| b.clone()),
                applied: s.applied.clone(),
                failed: s.failed.clone(),
            }),
            test: (self.arm == Arm::Follower
                && matches!(self.phase, Phase::Testing | Phase::Done)
                && self.saved.is_some())
            .then(|| TestView {
                pose: self
                    .test_joints()
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v))
                    .collect(),
                description: format!(
                    "base {:.0}° left, main arm {:.0}° forward of vertical, forearm {:.0}° below horizontal, claw {:.0} % open",
                    TEST_POSE[0],
                    90.0 - TEST_POSE[1],
                    -TEST_POSE[2],
                    TEST_POSE[3] * 100.0
                ),
                done: self.test_done,
            }),
            gripper_open_rad: open,
        }
    }

    /// The inputs of the arm at step `step`'s reference `input`: home, the holds, then
    /// the reference.
    fn pose_inputs(&self, step: usize, input: f64) -> [f64; 4] {
        let servo = CALIBRATION_ORDER[step];
        let mut inputs = [0.0, 90.0, 0.0, 0.0];
        for h in &self.plan.get(servo).holds {
            inputs[index(h.servo)] = h.input;
        }
        inputs[index(servo)] = input;
        inputs
    }

    fn instruction(&self) -> String {
        let servo = self.servo();
        let r = self.reference_of(self.step, self.reference);
        let what = format!(
            "{}: {} ({} = {})",
            title(servo),
            r.description,
            calibration::input_name(servo),
            show_input(servo, r.input)
        );
        match self.phase {
            Phase::Idle => "Calibrate the arm's servos (follower) or a leader arm's potentiometers.".into(),
            Phase::Starting => "Telling compute_ik to send nothing…".into(),
            Phase::Moving if self.estop => "E-stop engaged: the servos hold. Release it to go on.".into(),
            Phase::Moving => format!(
                "Moving {} into place, one servo at a time…",
                self.moving.map(|(m, _)| title(m.servo)).unwrap_or(title(servo))
            ),
            Phase::Jog => match self.arm {
                Arm::Follower => format!(
                    "Jog until the arm shows {what}, then mark. Reference {} of 2.",
                    ["A", "B"][self.reference]
                ),
                Arm::Leader => format!(
                    "Move the leader by hand until it shows {what}, hold it still and mark. Reference {} of 2.",
                    ["A", "B"][self.reference]
                ),
            },
            Phase::Reading => "Reading the leader's potentiometers…".into(),
            Phase::Review => "Every servo is derived: save to write the file and apply it.".into(),
            Phase::Saving => "Saving and applying…".into(),
            Phase::Testing => "Saved and applied. Moving to the test pose…".into(),
            Phase::Done if self.arm == Arm::Follower => {
                "Saved. Check the arm against the test pose's picture; finish, or calibrate again."
                    .into()
            }
            Phase::Done => "Saved. Move the leader and watch its joints beside the follower's; finish.".into(),
            Phase::Failed => "Stopped: see the error. Start again, or finish.".into(),
        }
    }
}

fn intersect(a: JogRange, b: JogRange) -> JogRange {
    let min_deg = a.min_deg.max(b.min_deg);
    let max_deg = a.max_deg.min(b.max_deg);
    if min_deg <= max_deg {
        JogRange { min_deg, max_deg }
    } else {
        b
    }
}

fn set_servo(servos: &mut ServoCalibrations, servo: ServoId, c: ServoCalibration) {
    *servo.of([
        &mut servos.base,
        &mut servos.shoulder,
        &mut servos.elbow,
        &mut servos.gripper,
    ]) = c;
}

fn describe(d: &Derivation) -> String {
    match d {
        Derivation::Servo(d) => format!(
            "offset {:.2}°, gain {:.3} ({}, {:.0} % of the shipped)",
            d.calibration.offset_deg,
            d.calibration.gain,
            match d.direction {
                Direction::AsShipped => "direction as shipped",
                Direction::Reversed => "reversed",
            },
            d.gain_ratio * 100.0
        ),
        Derivation::Leader(c) => format!(
            "{:.1} counts at {}, {:.1} at {}",
            c.counts_a, c.input_a, c.counts_b, c.input_b
        ),
    }
}

/// The joints (rad, by name) of the arm at servo inputs `inputs` (base_joint,
/// shoulder_joint, forearm elevation φ in deg; claw opening).
pub fn pose_joints(config: &ArmConfig, inputs: [f64; 4]) -> BTreeMap<&'static str, f64> {
    let [base, shoulder, phi, opening] = inputs;
    BTreeMap::from([
        ("base_joint", base.to_radians()),
        ("shoulder_joint", shoulder.to_radians()),
        ("elbow_joint", (phi - shoulder).to_radians()),
        ("gripper_joint", opening * config.geometry.gripper_open_rad),
    ])
}
