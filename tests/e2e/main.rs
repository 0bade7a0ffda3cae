//! End-to-end tests: real worker processes, real iceoryx2 shared memory.

mod actions;
mod async_step;
mod bad_input;
mod capture;
mod classic_rollouts;
mod cli;
mod concurrency;
mod daemon;
mod env_pool;
mod env_pool_remote;
mod failures;
mod fair_shares;
mod hub_bounds;
mod lab_netns;
mod lan_peer;
mod local_files;
mod lying_hub;
mod other_user;
mod python_worker;
mod rapier_rollouts;
mod remote_hubs;
mod remote_impostor;
mod remote_netns;
mod remote_pool_bench;
mod rendering;
mod replay_flood;
mod serve_defaults;
mod session_owner;
mod small_shm;
mod tls;
mod worker_binaries;
mod worker_lifetime;

/// Set for this test binary's processes: the config folder it made for them (children of a
/// test inherit it, and do not remove it).
const CONFIG_HOME_OF: &str = "ENVHUB_E2E_CONFIG_HOME";

/// Every process of this test binary (and the hubs and clients it starts) keeps envhub's
/// config (the hubs' identity key, the pinned hub keys) in a folder of its own, removed when
/// it exits: tests never pin the keys of their short-lived hubs into the user's `known_hubs`,
/// nor leave files behind. Set before `main`, while this process has one thread.
#[used]
#[unsafe(link_section = ".init_array")]
static CONFIG_HOME: extern "C" fn() = own_config_home;

extern "C" fn own_config_home() {
    if std::env::var_os(CONFIG_HOME_OF).is_some() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("e2e-config-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    if std::os::unix::fs::DirBuilderExt::mode(&mut std::fs::DirBuilder::new(), 0o700)
        .create(&dir)
        .is_err()
    {
        return;
    }
    // SAFETY: before `main`, one thread: nothing else reads the environment.
    unsafe {
        std::env::set_var("XDG_CONFIG_HOME", &dir);
        std::env::set_var(CONFIG_HOME_OF, &dir);
        std::env::remove_var("ENVHUB_KNOWN_HUBS");
        std::env::remove_var("ENVHUB_HUB_KEY");
        libc::atexit(remove_config_home);
    }
}

extern "C" fn remove_config_home() {
    if let Some(dir) = std::env::var_os(CONFIG_HOME_OF) {
        let _ = std::fs::remove_dir_all(dir);
    }
}
