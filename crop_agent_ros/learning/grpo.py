"""PPO with group-relative advantages for the family agent (``crop-sim train --task T --algorithm grpo``).

Why: evolution strategies beat the tuned rule because they compare their candidates on the same seasons (common
random numbers): without that, ES only ties the rule, as PPO does. A season's return swings with its weather by
thousands of USD/ha while one policy differs from another by tens; PPO's critic is meant to remove the weather's
share from its advantages, and does not manage it, even when it is told the season's weather to come. This learner gives PPO's update what ES has, in the manner
of GRPO (Shao et al. 2024, "DeepSeekMath"): no critic; fields in groups that share a season.

Each iteration:

- draws ``groups`` training seasons (from the task's pool of generated seasons, without replacement) and one
  draw of the task's episode terms per season; ``group_size`` fields run each season with its terms (common
  random numbers; each field draws its own observation noise from the iteration's stream);
- every field runs one whole season with its own exploration: gSDE (Raffin et al. 2021), the exploration
  weights drawn once per field and season, so a field's deviation from the mean action is consistent over its
  season (a policy's irrigation plan, not daily jitter that a quota averages away);
- a field's advantage, on every day of its season, is its season return (the task's reward, USD/ha: no shaping,
  discount or critic) minus its group's mean, divided by the iteration's standard deviation of those
  differences (:func:`group_advantages`);
- PPO's clipped surrogate (clip ``clip_range``) is minimised over ``n_epochs`` epochs of minibatches of
  ``batch_size`` field-days with Adam (step size decaying linearly from ``learning_rate`` to
  ``final_learning_rate``), gradient norm clipped at 0.5; only the policy (its network, action layer and
  exploration scale) learns, and only it is computed (the SB3 policy's value network is never evaluated).

The network, its observation and its action are the headline agent's (:mod:`.agent`: normalised raw
observation, action in mm, 64 x 64 by default). The run's policy files hold the deterministic actor in the
standard PPO container (as evolution strategies' do): at each checkpoint the learner's actor is copied into it.
``timesteps`` counts field-days of every field's season.
"""

from __future__ import annotations

import numpy as np

from ..policies.learned import AgentInterface
from .evolution import ActorVector, CheckpointSchedule

MAX_GRADIENT_NORM = 0.5


def group_advantages(returns: np.ndarray, group_size: int) -> np.ndarray:
    """Each field's return minus its group's mean (fields ``g K .. (g + 1) K - 1`` form group g), divided by the
    standard deviation of those differences over all fields (1e-8 added): a field's advantage."""
    returns = np.asarray(returns, dtype=float)
    centred = returns - returns.reshape(-1, group_size).mean(axis=1).repeat(group_size)
    return centred / (centred.std() + 1e-8)


def group_seasons(rng: np.random.Generator, pool_size: int, groups: int, group_size: int) -> np.ndarray:
    """The season of each of ``groups`` x ``group_size`` fields: ``groups`` distinct seasons of the pool, each
    repeated for its group's fields."""
    return np.repeat(rng.choice(pool_size, groups, replace=False), group_size)


def grpo(model, interface: AgentInterface, scenario, settings, seed: int, checkpoint) -> int:
    """Run group-relative PPO (module docstring) on ``model``'s actor for ``settings.timesteps`` field-days of
    ``scenario``'s training seasons (at most one iteration more); ``checkpoint(steps, early)`` is called with the
    learner's actor in ``model`` at the start, at the first iteration past 1 % of the budget (``early`` True) and
    then every ``settings.eval_freq`` field-days; the caller checkpoints the end. Returns the field-days run, with the
    final actor in ``model``."""
    import torch
    from gymnasium.vector import AutoresetMode
    from stable_baselines3 import PPO
    from crop_sim_ros.task import IrrigationVectorEnv
    from ..policies.rollout import draw_terms
    from .agent import network_spaces

    groups, group_size = settings.groups, settings.group_size
    n_fields = groups * group_size
    net_arch = list(settings.net_arch)
    learner = PPO("MlpPolicy", network_spaces(interface.input_size), use_sde=True, seed=seed, device="cpu",
                  policy_kwargs={"net_arch": net_arch, "log_std_init": settings.log_std_init}).policy
    ActorVector(learner).set(ActorVector(model.policy).get())  # start from the run's network
    actor = [*learner.mlp_extractor.policy_net.parameters(), *learner.action_net.parameters(), learner.log_std]
    optimizer = torch.optim.Adam(actor, lr=settings.learning_rate)
    rng = np.random.default_rng([seed, 977])
    env = IrrigationVectorEnv(n_fields, scenario, autoreset_mode=AutoresetMode.NEXT_STEP)

    def publish() -> None:
        ActorVector(model.policy).set(ActorVector(learner).get())

    steps = 0
    schedule = CheckpointSchedule(settings, checkpoint, publish)

    while steps < settings.timesteps:
        seasons = group_seasons(rng, scenario.n_seasons, groups, group_size)
        terms = {k: np.repeat(v, group_size)
                 for k, v in draw_terms(scenario, seasons[::group_size], int(rng.integers(2 ** 31))).items()}
        obs, _ = env.reset(seed=int(rng.integers(2 ** 31)), options={"season": seasons, "terms": terms})
        interface.reset()
        learner.reset_noise(n_fields)  # one exploration draw per field for its season
        running = np.ones(n_fields, dtype=bool)
        returns = np.zeros(n_fields)
        inputs_seen, actions_taken, log_probs, fields = [], [], [], []
        while running.any():
            inputs, _ = interface.observe(obs)
            with torch.no_grad():  # the actor alone (the learner's critic is never used)
                distribution = learner.get_distribution(torch.as_tensor(inputs))
                actions = distribution.get_actions()
                log_prob = distribution.log_prob(actions)
            actions = actions.numpy()
            rows = np.flatnonzero(running)
            inputs_seen.append(inputs[rows])
            actions_taken.append(actions[rows])
            log_probs.append(log_prob.numpy()[rows])
            fields.append(rows)
            obs, reward, terminated, truncated, _ = env.step(
                interface.to_mm(np.clip(actions, -1.0, 1.0)).reshape(-1, 1))
            returns[running] += reward[running]
            running &= ~(terminated | truncated)
        field = np.concatenate(fields)
        steps += len(field)
        advantage = torch.as_tensor(group_advantages(returns, group_size)[field], dtype=torch.float32)
        inputs_seen = torch.as_tensor(np.concatenate(inputs_seen))
        actions_taken = torch.as_tensor(np.concatenate(actions_taken))
        old_log_prob = torch.as_tensor(np.concatenate(log_probs))
        done = min(1.0, steps / settings.timesteps)
        for group in optimizer.param_groups:
            group["lr"] = settings.learning_rate + (settings.final_learning_rate - settings.learning_rate) * done
        for _ in range(settings.n_epochs):
            order = torch.randperm(len(field))
            for start in range(0, len(field), settings.batch_size):
                batch = order[start:start + settings.batch_size]
                log_prob = learner.get_distribution(inputs_seen[batch]).log_prob(actions_taken[batch])
                ratio = torch.exp(log_prob - old_log_prob[batch])
                clipped = torch.clamp(ratio, 1.0 - settings.clip_range, 1.0 + settings.clip_range)
                loss = -torch.min(ratio * advantage[batch], clipped * advantage[batch]).mean()
                optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(actor, MAX_GRADIENT_NORM)
                optimizer.step()
        schedule.after(steps)
    publish()
    return steps
