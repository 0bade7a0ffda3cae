//! `envhub-worker-rapier`: the worker of rapier's robot tasks. `envhub-worker` (and
//! `envhub-worker-mujoco`) list its adapter and hand its jobs over to it (see
//! [`envhub_worker::delegated`]); not meant to be started directly.

fn main() -> std::process::ExitCode {
    envhub_worker::set_adapters(|| vec![Box::new(envhub_rapier::Rapier)]);
    envhub_worker::run()
}
