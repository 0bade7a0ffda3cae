"""LeRobot's side of the LeRobot policy-server tests, run in LeRobot's interpreter by
`eval_peers.py lerobot-make-policy|lerobot-reference` (see there): the test policy saved with
LeRobot's `save_pretrained`, and the chunks LeRobot's own policy server computes for it."""

from __future__ import annotations

#: The small policy the LeRobot tests serve: ACT with random weights, a 32x32 camera and a
#: 5-D state, 7-D actions in chunks of 4 (no download: no pretrained backbone).
LEROBOT_CAMERA, LEROBOT_STATE, LEROBOT_ACTION, LEROBOT_CHUNK = (32, 32), 5, 7, 4


def lerobot_make_policy(folder: str) -> None:
    """Saves the test policy with LeRobot's `save_pretrained`, its processors beside it."""
    import torch
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    torch.manual_seed(0)
    h, w = LEROBOT_CAMERA
    config = ACTConfig(
        input_features={
            "observation.state": PolicyFeature(type=FeatureType.STATE, shape=(LEROBOT_STATE,)),
            "observation.images.front": PolicyFeature(type=FeatureType.VISUAL, shape=(3, h, w)),
        },
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(LEROBOT_ACTION,))},
        chunk_size=LEROBOT_CHUNK,
        n_action_steps=LEROBOT_CHUNK,
        pretrained_backbone_weights=None,
        dim_model=32,
        n_heads=2,
        dim_feedforward=64,
        n_encoder_layers=1,
        n_decoder_layers=1,
        use_vae=False,
        device="cpu",
    )
    policy = ACTPolicy(config)
    policy.save_pretrained(folder)
    stats = {
        "observation.state": {"mean": torch.zeros(LEROBOT_STATE), "std": torch.ones(LEROBOT_STATE)},
        "observation.images.front": {"mean": torch.full((3, 1, 1), 0.5), "std": torch.full((3, 1, 1), 0.25)},
        "action": {"mean": torch.zeros(LEROBOT_ACTION), "std": torch.full((LEROBOT_ACTION,), 2.0)},
    }
    pre, post = make_pre_post_processors(config, dataset_stats=stats)
    pre.save_pretrained(folder)
    post.save_pretrained(folder)


def lerobot_reference(folder: str, requests: str, out: str) -> None:
    """The action chunks LeRobot's own `PolicyServer` computes for pickled (features, raw
    observation) pairs, called in-process: its `SendPolicyInstructions` loads the policy, its
    `_predict_action_chunk` runs it, as it does for a client."""
    import pickle

    import torch
    from lerobot.async_inference.configs import PolicyServerConfig
    from lerobot.async_inference.helpers import RemotePolicyConfig, TimedObservation
    from lerobot.async_inference.policy_server import PolicyServer

    class Context:
        def peer(self) -> str:
            return "reference"

    class Setup:
        def __init__(self, data: bytes) -> None:
            self.data = data

    server = PolicyServer(PolicyServerConfig(host="127.0.0.1", port=1))
    server.Ready(None, Context())
    chunks = []
    with open(requests, "rb") as f:
        items = pickle.load(f)
    for i, (features, raw) in enumerate(items):
        if server.lerobot_features != features:
            config = RemotePolicyConfig("act", folder, features, LEROBOT_CHUNK, "cpu")
            server.SendPolicyInstructions(Setup(pickle.dumps(config)), Context())
        timed = server._predict_action_chunk(TimedObservation(timestamp=0.0, timestep=i, observation=raw, must_go=True))
        chunks.append(torch.stack([t.get_action() for t in timed]).numpy())
    with open(out, "wb") as f:
        pickle.dump(chunks, f)
