//! With `libmujoco`, this crate's test binaries and examples link libmujoco: give them an
//! rpath to its folder (`MUJOCO_DYNAMIC_LINK_DIR`, an absolute path that `.cargo/config.toml`
//! sets), so they run without `LD_LIBRARY_PATH`. They never leave `target/`; the binaries
//! that do (`envhub-worker-mujoco`) carry no such path and find the library at run time.

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    if std::env::var_os("CARGO_FEATURE_LIBMUJOCO").is_some()
        && let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR")
    {
        println!("cargo::rustc-link-arg=-Wl,-rpath,{}", dir.to_string_lossy());
    }
}
