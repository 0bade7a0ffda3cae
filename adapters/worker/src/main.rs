//! `envhub-worker`, the worker the hub starts. It links no libmujoco, so it starts anywhere:
//! with libmujoco 3.17.0 at hand it becomes `envhub-worker-mujoco` (see
//! [`envhub_worker::libmujoco`]); without, it hosts the other adapters and the MuJoCo ones
//! say what is missing. It must use nothing of `envhub_mujoco` but constants (a test checks
//! that the binary does not need libmujoco).

use envhub_worker::{Unlinked, libmujoco, native, set_adapters};

fn main() -> std::process::ExitCode {
    let missing = libmujoco::hand_over();
    set_adapters(move || native(Unlinked::both(&missing.reason, &missing.hint)));
    envhub_worker::run()
}
