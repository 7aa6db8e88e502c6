//! For any sequence of inputs (switches of any names and strictness, commands of every
//! commander, goals ending, the deadman, the e-stop, owners heard, time passing): in
//! every period at most one commander's output reaches each joint, and none while the
//! e-stop is engaged. Each commander tries to command every period; the arbiter's
//! `passes` is the gate its output goes through to `servo_angles`.

use arbiter::{Arbiter, Command, Controller, Event, Layout, Refusal, Strictness, Switch};
use proptest::prelude::*;
use std::time::{Duration, Instant};

const NAMES: [&str; 6] = [
    "teleop",
    "arm_controller",
    "gripper_controller",
    "leader_follower",
    "calibration",
    "nonsense",
];

fn names() -> impl Strategy<Value = Vec<String>> {
    proptest::collection::vec(0..NAMES.len(), 0..4)
        .prop_map(|v| v.into_iter().map(|i| NAMES[i].to_string()).collect())
}

fn event() -> impl Strategy<Value = Event> {
    let controller = (0..5usize).prop_map(|i| Controller::ALL[i]);
    let command = prop_oneof![
        Just(Command::ArmTarget),
        Just(Command::ArmAndClawTarget),
        Just(Command::ClawTarget),
        Just(Command::Trajectory),
        Just(Command::GripperGoal),
        Just(Command::LeaderSample),
    ];
    prop_oneof![
        4 => command.prop_map(Event::Command),
        2 => (names(), names(), any::<bool>(), prop_oneof![Just("wizard"), Just("panel")], any::<bool>()).prop_map(
            |(activate, deactivate, strict, owner, lease)| Event::Switch(Switch {
                activate,
                deactivate,
                strictness: if strict { Strictness::Strict } else { Strictness::BestEffort },
                owner: owner.into(),
                lease,
            })
        ),
        1 => controller.prop_map(Event::Finished),
        1 => any::<bool>().prop_map(Event::Deadman),
        1 => any::<bool>().prop_map(Event::Estop),
        1 => prop_oneof![Just("wizard"), Just("panel")].prop_map(|o| Event::OwnerAlive(o.into())),
        2 => Just(Event::Tick),
    ]
}

fn layout(claw: bool) -> Layout {
    Layout {
        arm: vec![
            "base_joint".into(),
            "shoulder_joint".into(),
            "elbow_joint".into(),
        ],
        gripper: claw.then(|| "gripper_joint".into()),
    }
}

fn claims(a: &Arbiter, c: Controller) -> Vec<usize> {
    let own = a.interfaces(c);
    a.layout()
        .joints()
        .enumerate()
        .filter(|(_, j)| own.contains(&format!("{j}/position")))
        .map(|(i, _)| i)
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1_000, ..ProptestConfig::default() })]

    #[test]
    fn at_most_one_commander_reaches_a_joint_in_any_period_and_none_under_the_estop(
        claw in any::<bool>(),
        steps in proptest::collection::vec((event(), 0u64..3_000), 1..80),
    ) {
        let t0 = Instant::now();
        let mut now = t0;
        let mut a = Arbiter::new(layout(claw));
        let joints = a.layout().joints().count();
        for (event, gap_ms) in steps {
            // time passes in periods; each period every commander tries to command
            now += Duration::from_millis(gap_ms);
            a.handle(Event::Tick, now);
            let before: Vec<_> = Controller::ALL.iter().map(|&c| a.mode(c).cloned()).collect();
            let calibrating = a.is_active(Controller::Calibration);
            let estop = a.estop();
            let command = matches!(event, Event::Command(_));
            let strict = matches!(&event, Event::Switch(s) if s.strictness == Strictness::Strict);
            let out = a.handle(event, now);
            for i in 0..joints {
                let reaching: Vec<_> = Controller::ALL
                    .into_iter()
                    .filter(|&c| a.passes(c) && claims(&a, c).contains(&i))
                    .collect();
                prop_assert!(reaching.len() <= 1, "joint {i} commanded by {reaching:?}");
                prop_assert_eq!(reaching.first().copied(), a.commander_of(i));
                if a.estop() {
                    prop_assert!(reaching.is_empty());
                }
            }
            // active controllers never claim one interface twice
            for c in Controller::ALL {
                for d in Controller::ALL {
                    if c < d && a.is_active(c) && a.is_active(d) {
                        let (x, y) = (claims(&a, c), claims(&a, d));
                        prop_assert!(x.iter().all(|j| !y.contains(j)), "{c} and {d} both active");
                    }
                }
            }
            match &out.result {
                // a command carried: its carrier's output reaches the servos now
                Ok(Some(carrier)) => prop_assert!(a.passes(*carrier)),
                // a refusal (a command's or a strict switch's) changes nothing
                Err(r) if command || strict => {
                    let after: Vec<_> = Controller::ALL.iter().map(|&c| a.mode(c).cloned()).collect();
                    prop_assert_eq!(&before, &after, "refused ({}) yet changed", r);
                    prop_assert!(out.changes.is_empty());
                }
                _ => {}
            }
            // the locks: nothing commands under the e-stop or beside a calibration
            if command && (estop || calibrating) {
                prop_assert!(out.result.is_err());
                let want = if estop { Refusal::Estop } else { Refusal::Calibrating };
                prop_assert_eq!(out.result.clone(), Err(want));
            }
        }
    }
}
