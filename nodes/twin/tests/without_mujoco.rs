//! Built without MuJoCo (the workspace's default build), the twin says what is missing
//! and how to get it, and exits with 3; `--mujoco-check` answers the same.
#![cfg(not(feature = "mujoco"))]
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::process::Command;

#[test]
fn the_twin_without_mujoco_says_what_is_missing() {
    for args in [
        &[][..],
        &["--mujoco-check"][..],
        &["--ros-args", "-p", "camera_fps:=0"][..],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_twin"))
            .args(args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(3), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("built without MuJoCo") && err.contains("install_mujoco.sh"),
            "{err}"
        );
    }
}
