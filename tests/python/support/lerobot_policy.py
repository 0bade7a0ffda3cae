"""Saves a small random-init ACT policy for an env config, as LeRobot saves a trained one
(`save_pretrained` of the policy and of its processors), for test_lerobot_plugin.py.

    python lerobot_policy.py SPEC.json OUT_DIR

SPEC: `{"type": "envhub", "config": {"task": "push-v3"}}`. Nothing is downloaded (no
pretrained backbone); the weights come from a fixed torch seed.
"""

from __future__ import annotations

import json
import sys


def main(spec_path: str, out: str) -> None:
    import torch
    from lerobot.envs.factory import make_env_config
    from lerobot.envs.utils import env_to_policy_features
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    spec = json.loads(open(spec_path).read())
    env_cfg = make_env_config(spec["type"], **spec.get("config", {}))
    features = env_to_policy_features(env_cfg)
    outputs = {k: f for k, f in features.items() if k == "action"}
    inputs = {k: f for k, f in features.items() if k != "action"}
    torch.manual_seed(0)
    cfg = ACTConfig(
        input_features=inputs,
        output_features=outputs,
        device="cpu",
        chunk_size=10,
        n_action_steps=10,
        dim_model=32,
        n_heads=2,
        dim_feedforward=64,
        n_encoder_layers=1,
        n_decoder_layers=1,
        use_vae=False,
        pretrained_backbone_weights=None,
        push_to_hub=False,
    )
    policy = ACTPolicy(cfg)
    policy.save_pretrained(out)
    pre, post = make_pre_post_processors(cfg)
    pre.save_pretrained(out)
    post.save_pretrained(out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
