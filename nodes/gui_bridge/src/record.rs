//! `record FILE`: every target an operator sends (from the panel or anything else on
//! `xyz_target` / `xyz_line_target` / `gripper_target`) as rows of a waypoint program
//! ([`crate::program`]), dwell = the time until the next one, mode `line` for a target
//! of `xyz_line_target` (empty for `xyz_target`'s: `play` sends each row back on its
//! topic); until Ctrl-C / SIGTERM.

use crate::program::{MoveMode, ProgramPoint, MAX_DWELL_S, PROGRAM_HEADER};
use anyhow::Context as _;
use futures::StreamExt;
use ros_plumbing::{topics, RosNode};
use std::future::Future;
use std::io::Write as _;
use std::path::Path;
use std::time::Instant;

/// Record into `path` (replaced) until `shutdown`.
pub async fn record(
    node: &mut RosNode,
    path: &Path,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    let shown = path.display();
    let mut file = std::fs::File::create(path).with_context(|| format!("cannot create {shown}"))?;
    writeln!(file, "{PROGRAM_HEADER}")?;
    let targets = node.subscribe_to(&topics::XYZ_TARGET)?;
    let line_targets = node.subscribe_to(&topics::XYZ_LINE_TARGET)?;
    let gripper = node.subscribe_to(&topics::GRIPPER_TARGET)?;
    println!(
        "recording {}, {} and {} into {shown}; Ctrl-C to stop",
        node.resolve(&topics::XYZ_TARGET)?,
        node.resolve(&topics::XYZ_LINE_TARGET)?,
        node.resolve(&topics::GRIPPER_TARGET)?
    );
    // each target with its kind: None on xyz_target, line on xyz_line_target
    let t = futures::stream::select(
        targets.async_stream().map(|r| r.map(|(m, _)| (m, None))),
        line_targets
            .async_stream()
            .map(|r| r.map(|(m, _)| (m, Some(MoveMode::Line)))),
    );
    let g = gripper.async_stream();
    tokio::pin!(t, g, shutdown);
    let mut pending: Option<(ProgramPoint, Instant)> = None;
    let mut opening: Option<f64> = None;
    let mut rows = 0;
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            Some(Ok((m, mode))) = t.next() => {
                if let Some((mut w, at)) = pending.take() {
                    // what `play` takes: an hour at most
                    w.dwell_s = at.elapsed().as_secs_f64().min(MAX_DWELL_S);
                    writeln!(file, "{}", w.to_row())?;
                    rows += 1;
                }
                let mut w = ProgramPoint::at([m.point.x, m.point.y, m.point.z]);
                w.gripper = opening;
                w.mode = mode;
                pending = Some((w, Instant::now()));
            }
            Some(Ok((m, _))) = g.next() => {
                // compute_ik refuses an opening outside 0 … 1: the claw stays as it was
                if (0.0..=1.0).contains(&m.data) {
                    opening = Some(m.data);
                }
                if let Some((w, _)) = pending.as_mut() {
                    w.gripper = opening;
                }
            }
        }
    }
    if let Some((w, _)) = pending {
        writeln!(file, "{}", w.to_row())?;
        rows += 1;
    }
    file.flush()?;
    println!("recorded {rows} waypoints into {shown}");
    Ok(())
}
