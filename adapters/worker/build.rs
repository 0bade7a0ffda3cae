//! With the `mujoco` feature the worker links libmujoco: give the binary (and its test
//! binaries) an rpath to the library's folder, `MUJOCO_DYNAMIC_LINK_DIR` (an absolute path
//! that `.cargo/config.toml` sets), so it runs without `LD_LIBRARY_PATH`.

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_MUJOCO").is_some()
        && let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR")
    {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{}", dir.to_string_lossy());
    }
}
