//! With the `mujoco` feature: the binaries and tests find MuJoCo's library where it was
//! linked from (an rpath to MUJOCO_DYNAMIC_LINK_DIR), with no LD_LIBRARY_PATH to set.
fn main() {
    println!("cargo:rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_some() {
        if let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR") {
            println!(
                "cargo:rustc-link-arg=-Wl,-rpath,{}",
                std::path::Path::new(&dir).display()
            );
        }
    }
}
