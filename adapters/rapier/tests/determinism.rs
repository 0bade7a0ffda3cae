//! Same seed → bit-identical episodes: two fresh env instances (as two worker processes would
//! create them) and one instance reseeded, over a whole scripted-free random episode.

use crate::common::{episode, make, random_policy};
use envhub_core::{EnvAdapter, EnvConfig};
use envhub_rapier::Rapier;

#[test]
fn same_seed_gives_bit_identical_episodes() {
    let config = EnvConfig {
        max_episode_steps: Some(120),
        ..EnvConfig::default()
    };
    for env_id in Rapier.list_envs() {
        let mut a = make(&env_id, &config);
        let mut b = make(&env_id, &config);
        let first = episode(&mut a, 7, &mut random_policy(3), true);
        // Another seed in between, so the reseed has something to undo.
        episode(&mut a, 8, &mut random_policy(4), false);
        let again = episode(&mut a, 7, &mut random_policy(3), true);
        let fresh = episode(&mut b, 7, &mut random_policy(3), true);
        assert_eq!(first, again, "{env_id}: reseeding changed the episode");
        assert_eq!(
            first, fresh,
            "{env_id}: a fresh instance gave another episode"
        );
        let other = episode(&mut b, 9, &mut random_policy(3), true);
        assert_ne!(
            first.obs[0], other.obs[0],
            "{env_id}: seeds 7 and 9 start alike"
        );
    }
}
