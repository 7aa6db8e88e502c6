//! `camera_node` binary: sets up ROS and runs [`camera_node::run`].

use camera_node::config::Config;
use camera_node::report::CameraCore;
use camera_node::{Capture, Handles};
use eezybot_msgs::diagnostic_msgs::DiagnosticStatus;
use eezybot_msgs::sensor_msgs::{CameraInfo, CompressedImage};
use ros_plumbing::diagnostics::DiagnosticsPublisher;
use ros_plumbing::{topics, RosNode, Shutdown, TopicPublisher};
use std::process::ExitCode;
use std::time::Instant;

struct RosOutputs {
    image: TopicPublisher<CompressedImage>,
    info: TopicPublisher<CameraInfo>,
    diagnostics: DiagnosticsPublisher,
}

impl camera_node::Outputs for RosOutputs {
    fn image(&self, msg: CompressedImage) {
        self.image.publish(msg);
    }
    fn camera_info(&self, msg: CameraInfo) {
        self.info.publish(msg);
    }
    fn diagnostics(&self, status: DiagnosticStatus) {
        self.diagnostics.publish(vec![status]);
    }
}

fn main() -> ExitCode {
    ros_plumbing::node::main(camera_node::spec(), serve)
}

/// Publish, start the capture thread and run the node until `shutdown`.
async fn serve(node: &mut RosNode, shutdown: Shutdown) -> anyhow::Result<()> {
    let params = node.params().clone();
    let config = Config::from_params(&params);
    let outputs = RosOutputs {
        image: node.publish_on(&topics::CAMERA_IMAGE)?,
        info: node.publish_on(&topics::CAMERA_INFO)?,
        diagnostics: node.diagnostics()?,
    };
    log::info!(
        "{} ready in ROS domain {}: {} {}x{} at {} fps on {} and {}",
        node.resolver().node_fqn(),
        node.domain_id(),
        config.device,
        config.width,
        config.height,
        config.fps,
        node.resolve(&topics::CAMERA_IMAGE)?,
        node.resolve(&topics::CAMERA_INFO)?
    );
    let diag_name = format!("{}: camera", node.resolver().node_name());
    let (capture, events) = Capture::start(&config)?;
    camera_node::run(Handles {
        core: CameraCore::new(config, diag_name, Instant::now()),
        outputs: &outputs,
        params,
        events,
        shutdown,
    })
    .await;
    capture.stop();
    Ok(())
}
