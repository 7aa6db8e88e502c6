//! Every transition of the arbiter, as a table (docs/nodes.md has the same rules): from a
//! state reached by events, one event, then the decision, the changes and who is active.
//! On a fixed clock: each event's time is given (ms after the start).

use arbiter::{
    Arbiter, Change, Command, Controller, Event, Layout, Refusal, Strictness, Switch, Why,
};
use std::time::{Duration, Instant};

use Controller::{
    ArmController as Arm, Calibration as Cal, GripperController as Grip, LeaderFollower as Lead,
    Teleop,
};

fn eezybot() -> Layout {
    Layout {
        arm: vec![
            "base_joint".into(),
            "shoulder_joint".into(),
            "elbow_joint".into(),
        ],
        gripper: Some("gripper_joint".into()),
    }
}

fn cmd(c: Command) -> Event {
    Event::Command(c)
}

fn switch(strictness: Strictness, activate: &[&str], deactivate: &[&str]) -> Event {
    Event::Switch(Switch {
        activate: activate.iter().map(|s| s.to_string()).collect(),
        deactivate: deactivate.iter().map(|s| s.to_string()).collect(),
        strictness,
        owner: "wizard".into(),
        lease: true,
    })
}

fn strict(activate: &[&str], deactivate: &[&str]) -> Event {
    switch(Strictness::Strict, activate, deactivate)
}

/// Calibration made active by its owner, "wizard", at 0 ms.
fn calibrating() -> Vec<(u64, Event)> {
    vec![(
        0,
        strict(&["calibration"], &["teleop", "gripper_controller"]),
    )]
}

fn following() -> Vec<(u64, Event)> {
    vec![(0, Event::Deadman(true)), (0, cmd(Command::LeaderSample))]
}

fn running() -> Vec<(u64, Event)> {
    vec![(0, cmd(Command::Trajectory))]
}

struct Row {
    rule: &'static str,
    given: Vec<(u64, Event)>,
    when: (u64, Event),
    result: Result<Option<Controller>, Refusal>,
    changes: Vec<Change>,
    active: Vec<Controller>,
}

fn row(
    rule: &'static str,
    given: Vec<(u64, Event)>,
    when: (u64, Event),
    result: Result<Option<Controller>, Refusal>,
    changes: Vec<Change>,
    active: &[Controller],
) -> Row {
    Row {
        rule,
        given,
        when,
        result,
        changes,
        active: active.to_vec(),
    }
}

fn following_joint() -> Refusal {
    Refusal::Following {
        joint: "base_joint".into(),
    }
}

fn table() -> Vec<Row> {
    use Change::{Activated, Deactivated, Skipped, Stopped};
    let claw_held = Refusal::Following {
        joint: "gripper_joint".into(),
    };
    vec![
        row(
            "at start teleop has the arm",
            vec![],
            (0, cmd(Command::ArmTarget)),
            Ok(Some(Teleop)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "at start gripper_controller has the claw (gripper_target)",
            vec![],
            (0, cmd(Command::ClawTarget)),
            Ok(Some(Grip)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "a joint_target naming the claw: teleop's and gripper_controller's",
            vec![],
            (0, cmd(Command::ArmAndClawTarget)),
            Ok(Some(Teleop)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "a trajectory takes the arm from teleop",
            vec![],
            (0, cmd(Command::Trajectory)),
            Ok(Some(Arm)),
            vec![Deactivated(Teleop, Why::PreemptedBy(Arm)), Activated(Arm)],
            &[Arm, Grip],
        ),
        row(
            "a new trajectory goal preempts the running one (arm_controller keeps the arm)",
            running(),
            (10, cmd(Command::Trajectory)),
            Ok(Some(Arm)),
            vec![],
            &[Arm, Grip],
        ),
        row(
            "a teleop target takes the arm from a running trajectory",
            running(),
            (10, cmd(Command::ArmTarget)),
            Ok(Some(Teleop)),
            vec![
                Deactivated(Arm, Why::PreemptedBy(Teleop)),
                Activated(Teleop),
            ],
            &[Teleop, Grip],
        ),
        row(
            "a teleop target takes the arm from a finished trajectory",
            vec![(0, cmd(Command::Trajectory)), (500, Event::Finished(Arm))],
            (900, cmd(Command::ArmTarget)),
            Ok(Some(Teleop)),
            vec![
                Deactivated(Arm, Why::PreemptedBy(Teleop)),
                Activated(Teleop),
            ],
            &[Teleop, Grip],
        ),
        row(
            "a joint_target naming the claw takes the arm from a trajectory",
            running(),
            (10, cmd(Command::ArmAndClawTarget)),
            Ok(Some(Teleop)),
            vec![
                Deactivated(Arm, Why::PreemptedBy(Teleop)),
                Activated(Teleop),
            ],
            &[Teleop, Grip],
        ),
        row(
            "a gripper_target while a trajectory has the arm moves the claw on its own",
            running(),
            (10, cmd(Command::ClawTarget)),
            Ok(Some(Grip)),
            vec![],
            &[Arm, Grip],
        ),
        row(
            "a gripper_target supersedes a running gripper goal",
            vec![(0, cmd(Command::GripperGoal))],
            (10, cmd(Command::ClawTarget)),
            Ok(Some(Grip)),
            vec![Stopped(Grip, Why::Superseded)],
            &[Teleop, Grip],
        ),
        row(
            "a joint_target naming the claw supersedes a running gripper goal",
            vec![(0, cmd(Command::GripperGoal))],
            (10, cmd(Command::ArmAndClawTarget)),
            Ok(Some(Teleop)),
            vec![Stopped(Grip, Why::Superseded)],
            &[Teleop, Grip],
        ),
        row(
            "an xyz_target during a gripper goal: both run",
            vec![(0, cmd(Command::GripperGoal))],
            (10, cmd(Command::ArmTarget)),
            Ok(Some(Teleop)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "a gripper goal beside teleop",
            vec![],
            (0, cmd(Command::GripperGoal)),
            Ok(Some(Grip)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "a new gripper goal preempts the running one (gripper_controller keeps the claw)",
            vec![(0, cmd(Command::GripperGoal))],
            (10, cmd(Command::GripperGoal)),
            Ok(Some(Grip)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "a trajectory beside a gripper goal: both run",
            vec![(0, cmd(Command::GripperGoal))],
            (10, cmd(Command::Trajectory)),
            Ok(Some(Arm)),
            vec![Deactivated(Teleop, Why::PreemptedBy(Arm)), Activated(Arm)],
            &[Arm, Grip],
        ),
        row(
            "the deadman held: the leader's first sample takes the arm and the claw",
            vec![(0, Event::Deadman(true))],
            (10, cmd(Command::LeaderSample)),
            Ok(Some(Lead)),
            vec![
                Deactivated(Teleop, Why::PreemptedBy(Lead)),
                Deactivated(Grip, Why::PreemptedBy(Lead)),
                Activated(Lead),
            ],
            &[Lead],
        ),
        row(
            "the leader takes the arm from a running trajectory",
            vec![(0, cmd(Command::Trajectory)), (0, Event::Deadman(true))],
            (10, cmd(Command::LeaderSample)),
            Ok(Some(Lead)),
            vec![
                Deactivated(Arm, Why::PreemptedBy(Lead)),
                Deactivated(Grip, Why::PreemptedBy(Lead)),
                Activated(Lead),
            ],
            &[Lead],
        ),
        row(
            "a leader sample with the deadman released is not followed",
            vec![],
            (0, cmd(Command::LeaderSample)),
            Err(Refusal::DeadmanReleased),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "following: a teleop target is refused (the deadman's holder has the arm)",
            following(),
            (10, cmd(Command::ArmTarget)),
            Err(following_joint()),
            vec![],
            &[Lead],
        ),
        row(
            "following: a trajectory is refused",
            following(),
            (10, cmd(Command::Trajectory)),
            Err(following_joint()),
            vec![],
            &[Lead],
        ),
        row(
            "following: a gripper goal is refused",
            following(),
            (10, cmd(Command::GripperGoal)),
            Err(claw_held.clone()),
            vec![],
            &[Lead],
        ),
        row(
            "following: a gripper_target is refused",
            following(),
            (10, cmd(Command::ClawTarget)),
            Err(claw_held),
            vec![],
            &[Lead],
        ),
        row(
            "following: samples keep it following",
            following(),
            (40, cmd(Command::LeaderSample)),
            Ok(Some(Lead)),
            vec![],
            &[Lead],
        ),
        row(
            "the deadman's release holds",
            following(),
            (10, Event::Deadman(false)),
            Ok(None),
            vec![Stopped(Lead, Why::DeadmanReleased)],
            &[Lead],
        ),
        row(
            "no leader sample within the timeout holds",
            following(),
            (50, Event::Tick),
            Ok(None),
            vec![Stopped(Lead, Why::LeaderTimeout)],
            &[Lead],
        ),
        row(
            "a sample within the timeout: still following",
            following(),
            (49, Event::Tick),
            Ok(None),
            vec![],
            &[Lead],
        ),
        row(
            "a holding leader gives the arm to a teleop target (the claw holds)",
            vec![
                (0, Event::Deadman(true)),
                (0, cmd(Command::LeaderSample)),
                (5, Event::Deadman(false)),
            ],
            (10, cmd(Command::ArmTarget)),
            Ok(Some(Teleop)),
            vec![
                Deactivated(Lead, Why::PreemptedBy(Teleop)),
                Activated(Teleop),
            ],
            &[Teleop],
        ),
        row(
            "a holding leader gives the claw to a gripper_target",
            vec![
                (0, Event::Deadman(true)),
                (0, cmd(Command::LeaderSample)),
                (5, Event::Deadman(false)),
            ],
            (10, cmd(Command::ClawTarget)),
            Ok(Some(Grip)),
            vec![Deactivated(Lead, Why::PreemptedBy(Grip)), Activated(Grip)],
            &[Grip],
        ),
        row(
            "the deadman held again: following again",
            vec![
                (0, Event::Deadman(true)),
                (0, cmd(Command::LeaderSample)),
                (5, Event::Deadman(false)),
                (20, Event::Deadman(true)),
            ],
            (30, cmd(Command::LeaderSample)),
            Ok(Some(Lead)),
            vec![],
            &[Lead],
        ),
        row(
            "the e-stop stops teleop's motion",
            vec![],
            (0, Event::Estop(true)),
            Ok(None),
            vec![Stopped(Teleop, Why::Estop)],
            &[Teleop, Grip],
        ),
        row(
            "the e-stop aborts a running trajectory and gripper goal",
            vec![
                (0, cmd(Command::Trajectory)),
                (0, cmd(Command::GripperGoal)),
            ],
            (10, Event::Estop(true)),
            Ok(None),
            vec![Stopped(Arm, Why::Estop), Stopped(Grip, Why::Estop)],
            &[Arm, Grip],
        ),
        row(
            "the e-stop holds the leader",
            following(),
            (10, Event::Estop(true)),
            Ok(None),
            vec![Stopped(Lead, Why::Estop)],
            &[Lead],
        ),
        row(
            "under the e-stop a target is refused",
            vec![(0, Event::Estop(true))],
            (10, cmd(Command::ArmTarget)),
            Err(Refusal::Estop),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "under the e-stop a gripper_target is refused",
            vec![(0, Event::Estop(true))],
            (10, cmd(Command::ClawTarget)),
            Err(Refusal::Estop),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "under the e-stop a trajectory is refused",
            vec![(0, Event::Estop(true))],
            (10, cmd(Command::Trajectory)),
            Err(Refusal::Estop),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "under the e-stop a leader sample is refused",
            vec![(0, Event::Deadman(true)), (0, Event::Estop(true))],
            (10, cmd(Command::LeaderSample)),
            Err(Refusal::Estop),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "under the e-stop nothing is activated",
            vec![(0, Event::Estop(true))],
            (10, strict(&["arm_controller"], &["teleop"])),
            Err(Refusal::Estop),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "under the e-stop a controller may be deactivated",
            vec![(0, Event::Estop(true))],
            (10, strict(&[], &["teleop"])),
            Ok(None),
            vec![Deactivated(Teleop, Why::Switched)],
            &[Grip],
        ),
        row(
            "the e-stop released: a target moves the arm again",
            vec![(0, Event::Estop(true)), (5, Event::Estop(false))],
            (10, cmd(Command::ArmTarget)),
            Ok(Some(Teleop)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "the e-stop engaged twice: stopped once",
            vec![(0, Event::Estop(true))],
            (10, Event::Estop(true)),
            Ok(None),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "calibration starts by a switch that frees its interfaces",
            vec![],
            (
                0,
                strict(&["calibration"], &["teleop", "gripper_controller"]),
            ),
            Ok(None),
            vec![
                Deactivated(Teleop, Why::Switched),
                Deactivated(Grip, Why::Switched),
                Activated(Cal),
            ],
            &[Cal],
        ),
        row(
            "calibration excludes targets",
            calibrating(),
            (10, cmd(Command::ArmTarget)),
            Err(Refusal::Calibrating),
            vec![],
            &[Cal],
        ),
        row(
            "calibration excludes the claw's targets",
            calibrating(),
            (10, cmd(Command::ClawTarget)),
            Err(Refusal::Calibrating),
            vec![],
            &[Cal],
        ),
        row(
            "calibration excludes trajectories",
            calibrating(),
            (10, cmd(Command::Trajectory)),
            Err(Refusal::Calibrating),
            vec![],
            &[Cal],
        ),
        row(
            "calibration excludes gripper goals",
            calibrating(),
            (10, cmd(Command::GripperGoal)),
            Err(Refusal::Calibrating),
            vec![],
            &[Cal],
        ),
        row(
            "calibration excludes the leader",
            {
                let mut g = calibrating();
                g.push((0, Event::Deadman(true)));
                g
            },
            (10, cmd(Command::LeaderSample)),
            Err(Refusal::Calibrating),
            vec![],
            &[Cal],
        ),
        row(
            "calibration excludes other controllers' activation",
            calibrating(),
            (10, strict(&["arm_controller"], &[])),
            Err(Refusal::DoubleClaim {
                joint: "base_joint".into(),
                first: Cal,
                second: Arm,
            }),
            vec![],
            &[Cal],
        ),
        row(
            "calibration ends by a switch",
            calibrating(),
            (
                10,
                strict(&["teleop", "gripper_controller"], &["calibration"]),
            ),
            Ok(None),
            vec![
                Deactivated(Cal, Why::Switched),
                Activated(Teleop),
                Activated(Grip),
            ],
            &[Teleop, Grip],
        ),
        row(
            "calibration gives the arm back when its owner is silent for the lease",
            calibrating(),
            (10_000, Event::Tick),
            Ok(None),
            vec![Deactivated(Cal, Why::OwnerGone)],
            &[],
        ),
        row(
            "calibration kept while its owner is heard",
            {
                let mut g = calibrating();
                g.push((6_000, Event::OwnerAlive("wizard".into())));
                g
            },
            (10_000, Event::Tick),
            Ok(None),
            vec![],
            &[Cal],
        ),
        row(
            "another's word does not renew the lease",
            {
                let mut g = calibrating();
                g.push((6_000, Event::OwnerAlive("stranger".into())));
                g
            },
            (10_000, Event::Tick),
            Ok(None),
            vec![Deactivated(Cal, Why::OwnerGone)],
            &[],
        ),
        row(
            "after calibration a target takes the free arm",
            {
                let mut g = calibrating();
                g.push((10, strict(&[], &["calibration"])));
                g
            },
            (20, cmd(Command::ArmTarget)),
            Ok(Some(Teleop)),
            vec![Activated(Teleop)],
            &[Teleop],
        ),
        row(
            "strict: two claims of one interface refused",
            vec![],
            (0, strict(&["arm_controller"], &[])),
            Err(Refusal::DoubleClaim {
                joint: "base_joint".into(),
                first: Teleop,
                second: Arm,
            }),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "strict: two of the asked claim one interface",
            vec![],
            (
                0,
                strict(
                    &["arm_controller", "leader_follower"],
                    &["teleop", "gripper_controller"],
                ),
            ),
            Err(Refusal::DoubleClaim {
                joint: "base_joint".into(),
                first: Arm,
                second: Lead,
            }),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "strict: an unknown name refuses it all",
            vec![],
            (0, strict(&["arm_controler"], &["teleop"])),
            Err(Refusal::UnknownController("arm_controler".into())),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "strict: activating an active controller refused",
            vec![],
            (0, strict(&["teleop"], &[])),
            Err(Refusal::AlreadyActive(Teleop)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "strict: deactivating an inactive controller refused",
            vec![],
            (0, strict(&[], &["arm_controller"])),
            Err(Refusal::NotActive(Arm)),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "strict: deactivated and activated in one switch restarts it",
            vec![],
            (0, strict(&["teleop"], &["teleop"])),
            Ok(None),
            vec![Deactivated(Teleop, Why::Switched), Activated(Teleop)],
            &[Teleop, Grip],
        ),
        row(
            "MoveIt's switch: arm_controller for teleop",
            vec![],
            (0, strict(&["arm_controller"], &["teleop"])),
            Ok(None),
            vec![Deactivated(Teleop, Why::Switched), Activated(Arm)],
            &[Arm, Grip],
        ),
        row(
            "a switch deactivating a running trajectory ends it",
            running(),
            (10, strict(&[], &["arm_controller"])),
            Ok(None),
            vec![Deactivated(Arm, Why::Switched)],
            &[Grip],
        ),
        row(
            "an empty switch changes nothing",
            vec![],
            (0, strict(&[], &[])),
            Ok(None),
            vec![],
            &[Teleop, Grip],
        ),
        row(
            "best effort: what can be done is done, the rest skipped with its reason",
            vec![],
            (
                0,
                switch(
                    Strictness::BestEffort,
                    &["nonsense", "arm_controller"],
                    &["teleop", "leader_follower"],
                ),
            ),
            Ok(None),
            vec![
                Deactivated(Teleop, Why::Switched),
                Activated(Arm),
                Skipped("leader_follower".into(), Refusal::NotActive(Lead)),
                Skipped(
                    "nonsense".into(),
                    Refusal::UnknownController("nonsense".into()),
                ),
            ],
            &[Arm, Grip],
        ),
        row(
            "best effort: a clashing activation skipped",
            vec![],
            (
                0,
                switch(
                    Strictness::BestEffort,
                    &["arm_controller", "leader_follower"],
                    &[],
                ),
            ),
            Ok(None),
            vec![
                Skipped(
                    "arm_controller".into(),
                    Refusal::DoubleClaim {
                        joint: "base_joint".into(),
                        first: Teleop,
                        second: Arm,
                    },
                ),
                Skipped(
                    "leader_follower".into(),
                    Refusal::DoubleClaim {
                        joint: "base_joint".into(),
                        first: Teleop,
                        second: Lead,
                    },
                ),
            ],
            &[Teleop, Grip],
        ),
        row(
            "best effort under the e-stop: deactivations only",
            vec![(0, Event::Estop(true))],
            (
                10,
                switch(Strictness::BestEffort, &["arm_controller"], &["teleop"]),
            ),
            Ok(None),
            vec![
                Deactivated(Teleop, Why::Switched),
                Skipped("arm_controller".into(), Refusal::Estop),
            ],
            &[Grip],
        ),
    ]
}

fn active(a: &Arbiter) -> Vec<Controller> {
    Controller::ALL
        .into_iter()
        .filter(|&c| a.is_active(c))
        .collect()
}

#[test]
fn every_transition_of_the_table() {
    let t0 = Instant::now();
    let at = |ms: u64| t0 + Duration::from_millis(ms);
    for r in table() {
        let mut a = Arbiter::new(eezybot());
        for (ms, e) in r.given {
            a.handle(e, at(ms));
        }
        let before = active(&a);
        let out = a.handle(r.when.1, at(r.when.0));
        assert_eq!(out.result, r.result, "{}", r.rule);
        assert_eq!(out.changes, r.changes, "{}", r.rule);
        assert_eq!(active(&a), r.active, "{}", r.rule);
        if out.result.is_err() {
            assert_eq!(active(&a), before, "{}: a refusal changes nothing", r.rule);
        }
    }
}

#[test]
fn an_arm_without_a_claw_has_no_gripper_commands() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(Layout {
        arm: vec!["j1".into(), "j2".into()],
        gripper: None,
    });
    assert_eq!(active(&a), [Teleop]);
    let out = a.handle(cmd(Command::ClawTarget), t0);
    assert_eq!(out.result, Err(Refusal::NoInterfaces(Grip)));
    let out = a.handle(cmd(Command::ArmAndClawTarget), t0);
    assert_eq!(out.result, Err(Refusal::NoInterfaces(Grip)));
    let out = a.handle(strict(&["gripper_controller"], &[]), t0);
    assert_eq!(out.result, Err(Refusal::NoInterfaces(Grip)));
    // its arm_controller and teleop claim the same two joints
    assert_eq!(a.interfaces(Arm), ["j1/position", "j2/position"]);
    assert_eq!(a.interfaces(Teleop), a.interfaces(Arm));
    assert!(a.interfaces(Grip).is_empty());
}

#[test]
fn list_controllers_names_states_and_interfaces() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(eezybot());
    a.handle(
        strict(&["arm_controller", "gripper_controller"], &["teleop"]),
        t0,
    );
    a.handle(cmd(Command::Trajectory), t0);
    let list = a.controllers();
    let names: Vec<_> = list.iter().map(|c| c.controller.name()).collect();
    assert_eq!(
        names,
        [
            "teleop",
            "arm_controller",
            "gripper_controller",
            "leader_follower",
            "calibration"
        ]
    );
    let states: Vec<_> = list.iter().map(|c| c.active).collect();
    assert_eq!(states, [false, true, true, false, false]);
    assert_eq!(
        list[1].interfaces,
        [
            "base_joint/position",
            "shoulder_joint/position",
            "elbow_joint/position"
        ]
    );
    assert_eq!(list[2].interfaces, ["gripper_joint/position"]);
    assert_eq!(list[3].interfaces.len(), 4);
    assert_eq!(list[1].detail, "executing a trajectory");
    assert_eq!(list[2].detail, "active, idle");
}

#[test]
fn the_deadline_is_the_leaders_timeout_or_the_owners_lease() {
    let t0 = Instant::now();
    let mut a = Arbiter::new(eezybot());
    assert_eq!(a.deadline(), None);
    a.handle(Event::Deadman(true), t0);
    a.handle(cmd(Command::LeaderSample), t0);
    assert_eq!(a.deadline(), Some(t0 + arbiter::DEFAULT_LEADER_TIMEOUT));
    a.handle(Event::Deadman(false), t0);
    assert_eq!(a.deadline(), None);
    a.handle(strict(&["calibration"], &["leader_follower"]), t0);
    assert_eq!(a.deadline(), Some(t0 + arbiter::DEFAULT_OWNER_LEASE));
}

#[test]
fn every_refusal_has_its_own_code() {
    let all = [
        Refusal::Estop,
        Refusal::Calibrating,
        following_joint(),
        Refusal::DeadmanReleased,
        Refusal::UnknownController("x".into()),
        Refusal::AlreadyActive(Teleop),
        Refusal::NotActive(Teleop),
        Refusal::DoubleClaim {
            joint: "j".into(),
            first: Teleop,
            second: Arm,
        },
        Refusal::NoInterfaces(Grip),
    ];
    let mut codes: Vec<_> = all.iter().map(Refusal::code).collect();
    codes.sort();
    codes.dedup();
    assert_eq!(codes.len(), all.len());
}

#[test]
fn an_arm_of_many_joints_is_arbitrated_without_a_limit_of_its_own() {
    // a serial arm has few joints; one of 200 (a generated URDF) must not crash the node
    let t0 = Instant::now();
    let arm: Vec<String> = (0..200).map(|i| format!("j{i}")).collect();
    let mut a = Arbiter::new(Layout {
        arm,
        gripper: Some("claw".into()),
    });
    assert_eq!(
        a.handle(cmd(Command::ArmTarget), t0).result,
        Ok(Some(Teleop))
    );
    assert_eq!(
        a.interfaces(Arm).len(),
        128,
        "the first 128 joints are claimed"
    );
    assert_eq!(
        a.handle(strict(&["arm_controller"], &["teleop"]), t0)
            .result,
        Ok(None)
    );
}
