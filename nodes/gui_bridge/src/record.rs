//! `record FILE`: every target an operator sends (from the panel or anything else on
//! `xyz_target` / `gripper_target`) as `x,y,z,gripper,dwell` rows, dwell = the time
//! until the next one; until Ctrl-C / SIGTERM.

use crate::teleop::{format_waypoint, Waypoint, WAYPOINT_HEADER};
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
    writeln!(file, "{WAYPOINT_HEADER}")?;
    let targets = node.subscribe_to(&topics::XYZ_TARGET)?;
    let gripper = node.subscribe_to(&topics::GRIPPER_TARGET)?;
    println!(
        "recording {} and {} into {shown}; Ctrl-C to stop",
        node.resolve(&topics::XYZ_TARGET)?,
        node.resolve(&topics::GRIPPER_TARGET)?
    );
    let (t, g) = (targets.async_stream(), gripper.async_stream());
    tokio::pin!(t, g, shutdown);
    let mut pending: Option<(Waypoint, Instant)> = None;
    let mut opening: Option<f64> = None;
    let mut rows = 0;
    loop {
        tokio::select! {
            _ = &mut shutdown => break,
            Some(Ok((m, _))) = t.next() => {
                if let Some((mut w, at)) = pending.take() {
                    w.dwell_s = at.elapsed().as_secs_f64();
                    writeln!(file, "{}", format_waypoint(&w))?;
                    rows += 1;
                }
                pending = Some((Waypoint { xyz: [m.point.x, m.point.y, m.point.z], gripper: opening, dwell_s: 0.0 }, Instant::now()));
            }
            Some(Ok((m, _))) = g.next() => {
                opening = Some(m.data);
                if let Some((w, _)) = pending.as_mut() {
                    w.gripper = opening;
                }
            }
        }
    }
    if let Some((w, _)) = pending {
        writeln!(file, "{}", format_waypoint(&w))?;
        rows += 1;
    }
    file.flush()?;
    println!("recorded {rows} waypoints into {shown}");
    Ok(())
}
