//! Embeds an rpath to the workspace's `.deps/lib` (filled by `make setup`) so `hitl`, its tests and
//! benches load libmujoco (stub feature) without LD_LIBRARY_PATH.
fn main() {
    println!("cargo:rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if let Ok(dir) = std::env::var("MUJOCO_DYNAMIC_LINK_DIR") {
        println!("cargo:rustc-link-arg=-Wl,-rpath,{dir}");
    }
}
