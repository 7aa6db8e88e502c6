//! A dataset row from a sampled frame: `observation.state` is the follower's joints,
//! `action` what was commanded for the frame.
//!
//! The action is, in this order:
//! 1. **the leader's joints while following**: the frame's deadman sample is held and a
//!    leader sample is fresh (LeRobot's teleoperation action: what the operator's arm
//!    asked, before the follower's limits and ramps);
//! 2. otherwise **compute_ik's commanded joints** (`joint_states`: a command stands until
//!    the next one, from the panel, MoveIt, a trajectory or the leader);
//! 3. before any command was heard, **the follower's own joints** (the arm is told to
//!    stay where it is).

use crate::inputs::{Picture, Sample};
use recorder_core::{Frame, Need};
use std::sync::Arc;

/// The sampler's inputs, in order: these four, then one per camera.
pub const INPUTS: [(&str, Need); 4] = [
    ("servo_state", Need::Required),
    ("joint_states", Need::Held),
    ("leader/joint_states", Need::Optional),
    ("leader/deadman", Need::Optional),
];
/// Input index of the follower's joints (`servo_state`).
pub const STATE: usize = 0;
/// Input index of compute_ik's commanded joints (`joint_states`).
pub const COMMAND: usize = 1;
/// Input index of the leader's joints.
pub const LEADER: usize = 2;
/// Input index of the leader's deadman.
pub const DEADMAN: usize = 3;
/// Input index of the first camera.
pub const FIRST_CAMERA: usize = 4;

/// Where a frame's action came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActionSource {
    /// The leader arm, followed.
    Leader,
    /// compute_ik's command.
    Command,
    /// No command yet: the follower's joints.
    State,
}

/// One row of the dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The frame's index in the episode's grid (dropped frames counted).
    pub grid_index: u64,
    /// The frame's instant, ns.
    pub t_ns: i64,
    /// `observation.state`.
    pub state: [f32; 4],
    /// `action`.
    pub action: [f32; 4],
    /// Where the action came from.
    pub source: ActionSource,
    /// One per camera, in order.
    pub images: Vec<Arc<Picture>>,
}

fn joints(v: &Option<Sample>) -> Option<[f64; 4]> {
    match v {
        Some(Sample::Joints(q)) => Some(*q),
        _ => None,
    }
}

fn f32s(q: [f64; 4]) -> [f32; 4] {
    q.map(|v| v as f32)
}

/// The row of a sampled frame with `cameras` cameras; `None` if a required input has a
/// sample of the wrong kind (the node never offers one).
pub fn compose(frame: &Frame<Sample>, cameras: usize) -> Option<Row> {
    let v = &frame.values;
    let state = joints(v.get(STATE)?)?;
    let following = matches!(v.get(DEADMAN), Some(Some(Sample::Deadman(true))));
    let leader = v.get(LEADER).and_then(joints);
    let (action, source) = match (following, leader, v.get(COMMAND).and_then(joints)) {
        (true, Some(q), _) => (q, ActionSource::Leader),
        (_, _, Some(q)) => (q, ActionSource::Command),
        _ => (state, ActionSource::State),
    };
    let mut images = Vec::with_capacity(cameras);
    for k in 0..cameras {
        match v.get(FIRST_CAMERA + k) {
            Some(Some(Sample::Image(p))) => images.push(p.clone()),
            _ => return None,
        }
    }
    Some(Row {
        grid_index: frame.index,
        t_ns: frame.t_ns,
        state: f32s(state),
        action: f32s(action),
        source,
        images,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(values: Vec<Option<Sample>>) -> Frame<Sample> {
        Frame {
            index: 3,
            t_ns: 100,
            ages_ns: vec![None; values.len()],
            values,
        }
    }

    #[test]
    fn the_action_is_the_leader_while_following_else_the_command_else_the_state() {
        let s = Some(Sample::Joints([1.0; 4]));
        let c = Some(Sample::Joints([2.0; 4]));
        let l = Some(Sample::Joints([3.0; 4]));
        let held = Some(Sample::Deadman(true));
        let free = Some(Sample::Deadman(false));
        let cases = [
            (
                vec![s.clone(), c.clone(), l.clone(), held.clone()],
                3.0,
                ActionSource::Leader,
            ),
            (
                vec![s.clone(), c.clone(), l.clone(), free],
                2.0,
                ActionSource::Command,
            ),
            (
                vec![s.clone(), c.clone(), None, held.clone()],
                2.0,
                ActionSource::Command,
            ),
            (vec![s.clone(), None, None, None], 1.0, ActionSource::State),
            (vec![s.clone(), None, l, held], 3.0, ActionSource::Leader),
        ];
        for (values, want, source) in cases {
            let r = compose(&frame(values.clone()), 0).unwrap();
            assert_eq!((r.action[0], r.source), (want, source), "{values:?}");
            assert_eq!(r.state, [1.0; 4]);
            assert_eq!((r.grid_index, r.t_ns), (3, 100));
        }
    }

    #[test]
    fn every_camera_has_its_image_in_order() {
        let s = Some(Sample::Joints([1.0; 4]));
        let a = Arc::new(Picture::Jpeg(vec![1]));
        let b = Arc::new(Picture::Jpeg(vec![2]));
        let values = vec![
            s.clone(),
            None,
            None,
            None,
            Some(Sample::Image(a.clone())),
            Some(Sample::Image(b.clone())),
        ];
        let r = compose(&frame(values), 2).unwrap();
        assert_eq!(r.images, [a, b]);
        assert!(compose(&frame(vec![s, None, None, None]), 1).is_none());
    }
}
