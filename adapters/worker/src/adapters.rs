//! Every adapter this worker binary hosts, in one explicit list.

use envhub_core::EnvAdapter;
use std::sync::OnceLock;

/// Set to `1` to list the test adapters (`null`) in `describe`, hence in the hub's catalog
/// (`ENVHUB_TEST_ADAPTERS`, declared with the other variables in `envhub_hub::env_vars`).
const TEST_ADAPTERS_VAR: &str = "ENVHUB_TEST_ADAPTERS";

/// The adapters users see, given the two MuJoCo ones (real or [`crate::Unlinked`], as the
/// binary can host them). Adding one is one line here. Those another binary hosts
/// ([`crate::delegated`], rapier's) come on top of every binary's list.
pub fn native(mujoco: [Box<dyn EnvAdapter>; 2]) -> Vec<Box<dyn EnvAdapter>> {
    let [mujoco, custom_mjcf] = mujoco;
    vec![
        Box::new(envhub_classic::ClassicControl),
        mujoco,
        custom_mjcf,
    ]
}

type AdapterList = Box<dyn Fn() -> Vec<Box<dyn EnvAdapter>> + Send + Sync>;

/// The running binary's list (its `main` sets it before [`crate::run`]).
static ALL: OnceLock<AdapterList> = OnceLock::new();

/// Sets the adapters this binary hosts, as a function that makes them (each command makes
/// its own). The first call wins.
pub fn set_adapters(all: impl Fn() -> Vec<Box<dyn EnvAdapter>> + Send + Sync + 'static) {
    let _ = ALL.set(Box::new(all));
}

/// The binary's own adapters, then those another binary hosts that it does not.
fn all() -> Vec<Box<dyn EnvAdapter>> {
    let mut list = own();
    for info in crate::delegated::ALL {
        if !list.iter().any(|a| a.name() == info.name) {
            list.push(Box::new(crate::delegated::Delegated(info)));
        }
    }
    list
}

fn own() -> Vec<Box<dyn EnvAdapter>> {
    ALL.get().map(|all| all()).unwrap_or_default()
}

/// Whether this binary hosts adapter `name` itself (not through another binary).
pub fn hosts_itself(name: &str) -> bool {
    own().iter().any(|a| a.name() == name)
}

/// Adapters for tests and benches only: served when a job names them, listed only when
/// `ENVHUB_TEST_ADAPTERS=1`.
fn testing() -> Vec<Box<dyn EnvAdapter>> {
    vec![Box::new(crate::null_env::NullAdapter)]
}

/// The adapters `describe` lists: [`all`], plus the test adapters when asked for.
pub fn listed() -> Vec<Box<dyn EnvAdapter>> {
    let mut list = all();
    if std::env::var(TEST_ADAPTERS_VAR).is_ok_and(|v| v == "1") {
        list.extend(testing());
    }
    list
}

/// Whether `name` is a test adapter (`describe` marks them, so the hub can keep them out of
/// its catalog while still launching them).
pub fn is_testing(name: &str) -> bool {
    testing().iter().any(|a| a.name() == name)
}

/// The adapter named `name`, test adapters included.
pub fn by_name(name: &str) -> Option<Box<dyn EnvAdapter>> {
    all()
        .into_iter()
        .chain(testing())
        .find(|a| a.name() == name)
}
