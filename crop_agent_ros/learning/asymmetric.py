"""PPO with a critic that knows the season's weather (``crop-sim train --task T --critic-hindsight``).

Why: on the quota tasks a season's return varies with its weather by thousands of USD/ha, while what one
day's decision changes is tens. A critic that sees only the observation cannot tell the two apart, so PPO's
advantages (return minus the critic's value) are mostly the weather's luck, and the gradient drowns in it.
Evolution strategies, which beat the rule, avoid this by running every candidate on the same seasons (common
random numbers). An asymmetric critic (Pinto et al. 2018) does it for PPO: the value network also sees what
the field's season still holds (:mod:`crop_sim_ros.task.hindsight`: its potential yield, the rain, ET0 and
radiation of the next 7, 21 and 63 days, the next three weeks' mean TMAX), so the luck is in the baseline and
the advantage is left with what the action did. A baseline may depend on anything the action does not change
(the weather does not depend on irrigation), so the policy gradient stays unbiased.

Measured on ``benton-quota`` (README, "A critic that knows the season's weather"): the critic fits the returns
about three times better (value loss 0.15 against 0.50), and the policy is no better than without it: the
weather's luck in the advantages is not what holds PPO back there.

The policy (the actor) sees only the agent's inputs (:class:`~.agent.AgentInterface`): the network layout is
``net_arch`` for both, the actor's first layer reading the first ``actor_inputs`` values of the input, the
critic's all of them. The policy files a run writes hold the actor alone, in the headline agent's standard
PPO container (:func:`actor_container`): loading and acting are as for any run, and nothing that acts ever
sees the hindsight values.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import MlpExtractor

from crop_sim_ros.task.hindsight import HINDSIGHT_NAMES, SeasonHindsight


class ActorSeesPrefix(MlpExtractor):
    """SB3's MlpExtractor whose policy network reads only the first ``actor_inputs`` features (the value network
    reads them all)."""

    def __init__(self, feature_dim: int, net_arch, activation_fn, device, actor_inputs: int):
        super().__init__(feature_dim, net_arch, activation_fn, device)
        self.actor_inputs = int(actor_inputs)
        self.policy_net = MlpExtractor(self.actor_inputs, net_arch, activation_fn, device).policy_net

    def forward(self, features):
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features):
        return self.policy_net(features[..., :self.actor_inputs])


class HindsightCriticPolicy(ActorCriticPolicy):
    """An ActorCriticPolicy whose actor sees the first ``actor_inputs`` values of the observation and whose critic
    sees the whole of it (the agent's inputs, then the hindsight values)."""

    def __init__(self, *args, actor_inputs: int, **kwargs):
        self.actor_inputs = int(actor_inputs)
        super().__init__(*args, **kwargs)

    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = ActorSeesPrefix(self.features_dim, self.net_arch, self.activation_fn, self.device,
                                             self.actor_inputs)


class HindsightScaler:
    """Fixed centring and scaling of the hindsight values (mean and std over every 3rd day of every season of the
    training pool), clipped to [-10, 10] as the agent's inputs are."""

    def __init__(self, hindsight: SeasonHindsight, n_days: np.ndarray):
        season = np.concatenate([np.full(len(range(0, int(n), 3)), m) for m, n in enumerate(n_days)])
        day = np.concatenate([np.arange(0, int(n), 3) for n in n_days])
        values = hindsight.values(season, day)
        self.hindsight = hindsight
        self.mean, self.std = values.mean(axis=0), np.maximum(values.std(axis=0), 1e-6)

    def __call__(self, season, day) -> np.ndarray:
        scaled = (self.hindsight.values(season, day) - self.mean) / self.std
        return np.clip(scaled, -10.0, 10.0).astype(np.float32)

    def record(self) -> dict:
        return {"names": list(HINDSIGHT_NAMES), "mean": self.mean.tolist(), "std": self.std.tolist()}


def actor_container(model, input_size: int, policy_kwargs: dict, exploration: dict):
    """A standard PPO model (``MlpPolicy`` on ``input_size`` inputs, the run's network layout and exploration)
    holding ``model``'s actor: its policy network, action layer and exploration scale. Its value network is a fresh
    one, never trained (the trained critic needs the hindsight values; acting does not use a critic)."""
    from stable_baselines3 import PPO
    from .agent import network_spaces

    container = PPO("MlpPolicy", network_spaces(input_size), policy_kwargs=policy_kwargs, device="cpu", verbose=0,
                    seed=0, **exploration)
    source, target = model.policy, container.policy
    target.mlp_extractor.policy_net.load_state_dict(source.mlp_extractor.policy_net.state_dict())
    target.action_net.load_state_dict(source.action_net.state_dict())
    target.log_std.data.copy_(source.log_std.data)
    return container
