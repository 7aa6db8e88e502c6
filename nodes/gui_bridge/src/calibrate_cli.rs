//! `gui_bridge calibrate [--leader]`: the calibration wizard on the command line, for
//! an arm without a browser at hand. The same [`Wizard`] as the web panel's Calibrate
//! view, driven by lines on standard input:
//!
//! | line | does |
//! |---|---|
//! | `+` / `-` | jog the servo a fine step (0.5°) |
//! | `++` / `--` | jog a coarse step (5°) |
//! | `j DEG` | jog by DEG servo degrees (at most 5 either way) |
//! | `m` | mark the reference the arm shows now |
//! | `b` | undo the last mark |
//! | `alt on` / `alt off` | use reference B's alternative (the base turned right) |
//! | `s` | save, apply, and run the test move |
//! | `t` | the test move again |
//! | `q` | cancel (or, once saved, finish) and exit |
//! | `.` | where the wizard is now |
//! | `?` | this list |
//!
//! Every change prints the wizard's instruction and where the servo is. Exit status: 0
//! saved, 1 cancelled or failed, 2 a usage or configuration error. Ctrl-C or the end of
//! the input cancels (compute_ik takes the arm back).

use crate::calibrate::{self as cal, Arm, Op, Wizard};
use crate::calibration_ros::{calibration_path, RosCalibration};
use crate::delivery::NotDelivered;
use crate::ros_outputs::RosOutputs;
use crate::{CalibrationControl, Outputs};
use anyhow::Context as _;
use eezybot_kinematics::ArmConfig;
use eezybot_msgs::Time;
use futures::StreamExt as _;
use ros_plumbing::{feedback, topics, RosNode};
use std::collections::BTreeMap;
use std::future::Future;
use std::time::{Duration, Instant};
use tokio::io::AsyncBufReadExt as _;

/// What the lines of standard input ask.
#[derive(Clone, Debug, PartialEq)]
pub enum Line {
    /// A wizard operation.
    Op(Op),
    /// Print the commands.
    Help,
    /// Leave: cancel, or finish once saved.
    Quit,
    /// Print where the wizard is.
    Status,
    /// Nothing (an empty line).
    Nothing,
}

/// The commands, for `?`.
pub const HELP: &str =
    "+ / - fine jog (0.5°), ++ / -- coarse jog (5°), j DEG jog by DEG, m mark, b back, \
alt on|off reference B's alternative, s save, t test move again, . status, q quit, ? this list";

/// Read one line of input.
///
/// # Examples
/// ```
/// use gui_bridge::calibrate::Op;
/// use gui_bridge::calibrate_cli::{parse_line, Line};
/// assert_eq!(parse_line("++"), Ok(Line::Op(Op::Jog(5.0))));
/// assert_eq!(parse_line(" j -1.5 "), Ok(Line::Op(Op::Jog(-1.5))));
/// assert!(parse_line("j lots").is_err());
/// ```
pub fn parse_line(line: &str) -> Result<Line, String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let fine = eezybot_kinematics::calibration::FINE_STEP_DEG;
    let coarse = eezybot_kinematics::calibration::COARSE_STEP_DEG;
    Ok(match words.as_slice() {
        [] => Line::Nothing,
        ["+"] => Line::Op(Op::Jog(fine)),
        ["-"] => Line::Op(Op::Jog(-fine)),
        ["++"] => Line::Op(Op::Jog(coarse)),
        ["--"] => Line::Op(Op::Jog(-coarse)),
        ["j" | "jog", deg] => Line::Op(Op::Jog(
            deg.parse::<f64>()
                .ok()
                .filter(|d| d.is_finite())
                .ok_or_else(|| format!("`{deg}` is no number of degrees"))?,
        )),
        ["m" | "mark"] => Line::Op(Op::Mark),
        ["b" | "back"] => Line::Op(Op::Back),
        ["alt", "on"] => Line::Op(Op::Alternative(true)),
        ["alt", "off"] => Line::Op(Op::Alternative(false)),
        ["s" | "save"] => Line::Op(Op::Save),
        ["t" | "test"] => Line::Op(Op::Test),
        ["q" | "quit"] => Line::Quit,
        ["?" | "h" | "help"] => Line::Help,
        ["." | "status"] => Line::Status,
        _ => return Err(format!("`{}`: not a command ({HELP})", line.trim())),
    })
}

/// What the user sees after a change: the instruction, the servo, the marks.
pub fn describe(view: &crate::message::CalibrationView) -> String {
    let mut out = String::new();
    if let Some(step) = view.steps.get(view.step) {
        let marks: Vec<String> = view
            .steps
            .iter()
            .map(|s| {
                let m = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.1}"));
                format!("{} {}/{}", s.title, m(s.marks[0]), m(s.marks[1]))
            })
            .collect();
        out.push_str(&format!(
            "[{} {}/4 {}] ",
            view.phase,
            view.step + 1,
            step.title
        ));
        let driving = matches!(view.phase.as_str(), "moving" | "jog" | "review");
        if let (Some(c), Some(j), true) = (view.commanded_deg, &view.jog, driving) {
            out.push_str(&format!(
                "servo at {c:.1}° (servo_state {}; may jog {:.1}° … {:.1}°) ",
                view.state_deg
                    .map_or("–".to_string(), |s| format!("{s:.1}°")),
                j.min_deg,
                j.max_deg
            ));
        }
        if let Some(c) = view.counts {
            out.push_str(&format!(
                "leader counts A0–A3 {:.0} {:.0} {:.0} {:.0} ",
                c[0], c[1], c[2], c[3]
            ));
        }
        out.push_str(&format!("marks: {}\n", marks.join(", ")));
    }
    out.push_str(&format!("  {}\n", view.instruction));
    if let Some(e) = &view.error {
        out.push_str(&format!("  ! {e}\n"));
    }
    if let Some(saved) = &view.saved {
        out.push_str(&format!(
            "  saved to {} (previous: {}); applied to {}{}\n",
            saved.path.as_deref().unwrap_or("nothing"),
            saved.backup.as_deref().unwrap_or("none"),
            saved.applied.join(", "),
            if saved.failed.is_empty() {
                String::new()
            } else {
                format!("; NOT applied: {}", saved.failed.join("; "))
            }
        ));
    }
    out
}

/// Run the wizard on `node` for `arm` until the user quits, the input ends or
/// `shutdown` resolves.
pub async fn calibrate(
    node: &mut RosNode,
    leader: bool,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let params = node.params().clone();
    let arm_config = params.string("arm_config").unwrap_or_default();
    let config = ArmConfig::load_or_shipped(&arm_config).map_err(anyhow::Error::msg)?;
    let mut wizard = Wizard::new(config).map_err(|e| anyhow::anyhow!("{e}"))?;
    let outputs = RosOutputs::new(node)?;
    let servo_state = node.subscribe_to(&topics::SERVO_STATE)?;
    let diagnostics = node.subscribe_to(&topics::DIAGNOSTICS)?;
    let estop = node.subscribe_to(&topics::ESTOP)?;
    let joint_states = node.subscribe_to(&topics::JOINT_STATES)?;
    let path = calibration_path(
        &params.string("calibration_file").unwrap_or_default(),
        &arm_config,
    );
    let names = crate::NodeNames::from_params(&params);
    let node = std::cell::RefCell::new(node);
    let control = RosCalibration::new(&node, path, &names.ik);
    println!(
        "calibrating the {} arm; the result goes to {}\n{HELP}",
        if leader { "leader" } else { "follower" },
        control.path().display()
    );
    tokio::pin!(shutdown);
    if !leader {
        // compute_ik must go silent before anything moves: its parameter services first
        tokio::select! {
            r = control.wait_ready(&names.ik, Duration::from_secs(10)) => r.map_err(|e| {
                NotDelivered::NotCalibrated(format!(
                    "calibration not started: {0}'s parameters do not answer ({e}): is {0} running (ik_node)?", names.ik
                ))
            })?,
            _ = &mut shutdown => {
                return Err(NotDelivered::NotCalibrated("calibration cancelled (signal) before it started: nothing saved".into()).into());
            }
        }
    }
    // the nodes heard on diagnostics, by name: when last
    let mut heard: BTreeMap<String, Instant> = BTreeMap::new();
    let running = |heard: &BTreeMap<String, Instant>, within: Duration| -> Vec<String> {
        names
            .calibrated()
            .filter(|n| heard.get(*n).is_some_and(|at| at.elapsed() < within))
            .map(str::to_string)
            .collect()
    };
    let mut lines = tokio::io::BufReader::new(tokio::io::stdin()).lines();
    let mut servo_state = servo_state.async_stream().boxed_local();
    let mut diagnostics = diagnostics.async_stream().boxed_local();
    let mut estop = estop.async_stream().boxed_local();
    let mut joint_states = joint_states.async_stream().boxed_local();
    let mut tick = tokio::time::interval(Duration::from_millis(250));
    let arm = if leader { Arm::Leader } else { Arm::Follower };
    let mut started = false;
    // servo_state first: a follower's wizard starts where the servos are
    let start_by = Instant::now() + Duration::from_secs(5);
    let mut saved = false;
    let mut shown_errors: Vec<String> = vec![];
    loop {
        let mut fx = vec![];
        if !started && (leader || Instant::now() > start_by || wizard_has_state(&wizard)) {
            started = true;
            match wizard.request(Op::Start(arm), Instant::now()) {
                Ok(f) => fx = f,
                Err(e) => {
                    return Err(NotDelivered::NotCalibrated(format!(
                        "calibration not started: {e}"
                    ))
                    .into())
                }
            }
        } else {
            tokio::select! {
                _ = &mut shutdown => {
                    cancel(&mut wizard, &control).await;
                    return Err(NotDelivered::NotCalibrated("calibration cancelled (signal): nothing saved".into()).into());
                }
                line = lines.next_line() => {
                    let line = line.context("reading standard input")?;
                    let Some(line) = line else {
                        if saved {
                            return Ok(());
                        }
                        cancel(&mut wizard, &control).await;
                        return Err(NotDelivered::NotCalibrated("end of input: calibration cancelled, nothing saved".into()).into());
                    };
                    match parse_line(&line) {
                        Ok(Line::Nothing) => continue,
                        Ok(Line::Help) => { println!("{HELP}"); continue; }
                        Ok(Line::Status) => { print!("{}", describe(&wizard.view())); continue; }
                        Ok(Line::Quit) => {
                            if saved {
                                let _ = wizard.request(Op::Finish, Instant::now());
                                return Ok(());
                            }
                            cancel(&mut wizard, &control).await;
                            return Err(NotDelivered::NotCalibrated("calibration cancelled: nothing saved".into()).into());
                        }
                        Ok(Line::Op(op)) => match wizard.request(op, Instant::now()) {
                            Ok(f) => fx = f,
                            Err(e) => fx = { println!("  refused: {e}"); wizard.refused(&e) },
                        },
                        Err(e) => { println!("  {e}"); continue; }
                    }
                }
                Some(Ok((msg, _))) = servo_state.next() => {
                    if let Some(deg) = crate::panel::servo_degrees(&msg) {
                        fx = wizard.on_servo_state(deg, Instant::now());
                    }
                }
                Some(Ok((msg, _))) = diagnostics.next() => {
                    for f in feedback::decode(&msg) {
                        if let Some(n) = f.node {
                            heard.insert(n, Instant::now());
                        }
                    }
                    if let Some(counts) = crate::panel::leader_counts(&msg) {
                        let before = wizard.view();
                        fx = wizard.on_leader_counts(counts, Instant::now());
                        // live counts alone are no news worth a line
                        if wizard.view().steps == before.steps && wizard.view().phase == before.phase {
                            fx.retain(|e| *e != cal::Effect::View);
                        }
                    }
                }
                Some(Ok((msg, _))) = estop.next() => fx = wizard.on_estop(msg.data, Instant::now()),
                Some(Ok((msg, _))) = joint_states.next() => {
                    let joints = msg.name.iter().cloned().zip(msg.position.iter().copied()).collect();
                    fx = wizard.on_joint_states(&joints);
                }
                _ = tick.tick() => fx = wizard.on_tick(Instant::now()),
            }
        }
        // the wizard's effects, and the effects of their outcomes, in order
        let mut queue: std::collections::VecDeque<cal::Effect> = fx.into();
        let mut printed = false;
        while let Some(e) = queue.pop_front() {
            match e {
                cal::Effect::SetCalibrating(on) => {
                    let r = control.set_calibrating(on).await;
                    queue.extend(wizard.on_calibrating_set(on, r, Instant::now()));
                }
                cal::Effect::ServoAngles(deg) => control.servo_angles(deg, Time::now()),
                cal::Effect::Save(mut job) => {
                    job.nodes = running(&heard, Duration::from_secs(3));
                    for name in &job.nodes {
                        // matched before the save sets their arm_config (made when heard)
                        if let Err(e) = control.wait_ready(name, Duration::from_secs(3)).await {
                            log::warn!("calibration: {name}: {e}");
                        }
                    }
                    let outcome = control.save(*job).await;
                    saved = outcome.written.is_ok();
                    queue.extend(wizard.on_saved(outcome, Instant::now()));
                }
                cal::Effect::JointTarget(q) => outputs.joint_target(&q, Time::now()),
                cal::Effect::View => {
                    if !printed {
                        let view = wizard.view();
                        print!("{}", describe(&view));
                        // a step's refusal once, when it comes
                        let errors: Vec<Option<String>> =
                            view.steps.iter().map(|s| s.error.clone()).collect();
                        for (s, e) in view.steps.iter().zip(&errors) {
                            if let Some(e) = e.as_ref().filter(|e| !shown_errors.contains(e)) {
                                println!("  {} refused: {e}", s.title);
                            }
                        }
                        shown_errors = errors.into_iter().flatten().collect();
                        printed = true;
                    }
                }
                cal::Effect::Log(level, text) => log::log!(level, "{text}"),
            }
        }
        // let the parameter clients of the nodes heard match before a save
        control.prepare(&running(&heard, Duration::MAX));
    }
}

fn wizard_has_state(w: &Wizard) -> bool {
    w.has_servo_state()
}

/// Leave the wizard: compute_ik takes the arm back if it was told to send nothing.
async fn cancel(wizard: &mut Wizard, control: &RosCalibration<'_, '_>) {
    if wizard.holds_compute_ik() {
        if let Err(e) = control.set_calibrating(false).await {
            eprintln!("the arm could not be given back to compute_ik ({e}): `ros2 control switch_controllers --deactivate calibration`");
        }
    }
    let _ = wizard.request(Op::Cancel, Instant::now());
}
