//! The shared `Env` contract suite on every task.

use envhub_conformance::check_env;
use envhub_core::{EnvAdapter, EnvConfig};
use envhub_rapier::Rapier;

#[test]
fn every_task_conforms() {
    let adapter = Rapier;
    for env_id in adapter.list_envs() {
        // A short limit: random rollouts over several episodes stay quick.
        let config = EnvConfig {
            max_episode_steps: Some(60),
            ..EnvConfig::default()
        };
        check_env(&adapter, &env_id, &config, 200);
    }
}
