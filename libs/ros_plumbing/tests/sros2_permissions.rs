//! The SROS2 permissions (`ros_plumbing::sros2`) against what the nodes' sources do: a
//! node that calls another node's parameter services (`RemoteParameters`) must be
//! granted them, or under Enforce access control refuses its client and it stops; so
//! must a node that drives a recorder (`EpisodeClient`: its services and its `task`).

use ros_plumbing::sros2::{Role, PC_NODES, PI_NODES, REMOTE_PARAMETER_CALLS};
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_node_that_calls_remote_parameters_is_granted_them() {
    let nodes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../nodes");
    let mut callers = Vec::new();
    for node in PC_NODES.iter().chain(PI_NODES) {
        let mut files = Vec::new();
        rust_files(&nodes.join(node).join("src"), &mut files);
        assert!(
            !files.is_empty(),
            "no sources for {node} in {}",
            nodes.display()
        );
        if files.iter().any(|f| {
            std::fs::read_to_string(f)
                .unwrap_or_default()
                .contains("RemoteParameters::new(")
        }) {
            callers.push(*node);
        }
    }
    assert!(callers.contains(&"gui_bridge"), "{callers:?}");
    for caller in &callers {
        let calls: Vec<_> = REMOTE_PARAMETER_CALLS
            .iter()
            .filter(|(c, _, _)| c == caller)
            .collect();
        assert!(
            !calls.is_empty(),
            "{caller} calls RemoteParameters: add it to sros2::REMOTE_PARAMETER_CALLS"
        );
        let role = if PI_NODES.contains(caller) {
            Role::Pi
        } else {
            Role::Pc
        };
        let rules = role.rules("/").unwrap();
        for (_, callee, services) in calls {
            // remote_params.rs creates clients of get_parameters and set_parameters
            for srv in ["get_parameters", "set_parameters"] {
                assert!(services.contains(&srv), "{caller} -> {callee}: {srv}");
                assert!(rules.publish.contains(&format!("rq/{callee}/{srv}Request")));
                assert!(rules.subscribe.contains(&format!("rr/{callee}/{srv}Reply")));
            }
        }
    }
}

#[test]
fn every_node_that_drives_a_recorder_is_granted_its_services_and_task() {
    let nodes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../nodes");
    let mut callers = Vec::new();
    for node in PC_NODES.iter().chain(PI_NODES) {
        let mut files = Vec::new();
        rust_files(&nodes.join(node).join("src"), &mut files);
        if files.iter().any(|f| {
            std::fs::read_to_string(f)
                .unwrap_or_default()
                .contains("EpisodeClient::new(")
        }) {
            callers.push(*node);
        }
    }
    // gui_bridge's Record card, and the recorder's command line
    assert!(callers.contains(&"gui_bridge"), "{callers:?}");
    for caller in &callers {
        let role = if PI_NODES.contains(caller) {
            Role::Pi
        } else {
            Role::Pc
        };
        let rules = role.rules("/").unwrap();
        // episodes.rs: the three Trigger services, and the recorder's task parameter
        for s in ["start_episode", "save_episode", "discard_episode"] {
            let s = format!("recorder/{s}");
            assert!(
                rules.publish.contains(&format!("rq/{s}Request")),
                "{caller}: {s}"
            );
            assert!(
                rules.subscribe.contains(&format!("rr/{s}Reply")),
                "{caller}: {s}"
            );
        }
        assert!(
            rules.publish.contains("rq/recorder/set_parametersRequest"),
            "{caller} sets the recorder's task: add it to sros2::REMOTE_PARAMETER_CALLS"
        );
    }
}
