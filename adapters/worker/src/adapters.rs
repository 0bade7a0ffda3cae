//! Every adapter this worker binary hosts, in one explicit list.

use envhub_core::EnvAdapter;

/// The adapters compiled into this binary. Adding one is one line here.
pub fn all() -> Vec<Box<dyn EnvAdapter>> {
    vec![
        Box::new(envhub_classic::ClassicControl),
        Box::new(envhub_mujoco::Mujoco::default()),
        Box::new(envhub_mujoco::CustomMjcf::default()),
        Box::new(envhub_rapier::Rapier),
        Box::new(crate::null_env::NullAdapter),
    ]
}

/// The adapter named `name`.
pub fn by_name(name: &str) -> Option<Box<dyn EnvAdapter>> {
    all().into_iter().find(|a| a.name() == name)
}
