//! With `libmujoco`, this crate's test binaries and examples link libmujoco: give them an
//! rpath to its folder (`MUJOCO_DYNAMIC_LINK_DIR`, an absolute path that `.cargo/config.toml`
//! sets), so they run without `LD_LIBRARY_PATH`. `envhub-worker`'s build script does the same
//! for the worker binary.

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_LIBMUJOCO").is_some()
        && let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR")
    {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{}", dir.to_string_lossy());
    }
}
