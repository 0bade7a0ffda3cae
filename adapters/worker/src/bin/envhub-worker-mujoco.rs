//! `envhub-worker-mujoco`: the worker with every adapter, MuJoCo's included. It links
//! libmujoco and has no RUNPATH: `envhub-worker` starts it with the library's folder on
//! `LD_LIBRARY_PATH` (see [`envhub_worker::libmujoco`]); not meant to be started directly.

use envhub_worker::{native, set_adapters};

fn main() -> std::process::ExitCode {
    set_adapters(|| {
        native([
            Box::new(envhub_mujoco::Mujoco::default()),
            Box::new(envhub_mujoco::CustomMjcf::default()),
        ])
    });
    envhub_worker::run()
}
