"""Evolution strategies for the family agent (``crop-sim train --task T --algorithm es``): the deterministic
policy improved directly on its own return.

PPO improves the return of its *noisy* policy; what is evaluated (and what a farm runs) is the mean action.
On the quota tasks the two differ by more than PPO's gain over the tuned rule: a cloned planner's policy returns
14,624 USD/ha on benton-quota's validation seasons with a little exploration noise and 15,269 without, and PPO
moves it towards the first. Evolution strategies (Salimans et al. 2017,
"Evolution Strategies as a Scalable Alternative to Reinforcement Learning") perturb the network's *parameters*
instead of its actions, so every candidate is a deterministic policy and the objective is the one evaluated:

- a generation draws ``seasons`` training seasons (from the task's pool of generated seasons), their episode
  terms and an observation-noise seed; ``pairs`` antithetic candidates theta +- sigma x eps_i each run all of
  them (the same seasons and terms for every candidate: common random numbers, so candidates differ by their
  parameters, not by their weather; the observation noise is one stream over all the generation's fields, so each
  field draws its own);
- a candidate's fitness is its mean season return (the task's reward, USD/ha, unshaped: no critic, no
  discount, no bootstrap); fitnesses are replaced by centred ranks in [-0.5, 0.5];
- the gradient estimate sum_i (rank(+i) - rank(-i)) eps_i / (2 n sigma) moves theta by Adam, with a step
  size decaying linearly from ``learning_rate`` to ``final_learning_rate`` over ``timesteps``.

The network, its observation and its action are the headline agent's (:mod:`.agent`: normalised raw
observation, action in mm); it lives in a Stable-Baselines3 PPO policy (the container the policy file and
:class:`~.agent.LearnedPolicy` load; its value network and exploration scale are unused). The environment steps
a run uses (``timesteps``) are field-days of every candidate's seasons; ES starts from a fresh network. The
settings (``pairs``, ``noise_std``, ``seasons``, learning rates) are the recipe of
:mod:`.hyperparameters` (``hyperparams/es.yml``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..policies.learned import AgentInterface

class ActorVector:
    """The actor of a Stable-Baselines3 ``ActorCriticPolicy`` (``mlp_extractor.policy_net``: Linear and Tanh
    layers; ``action_net``: Linear) as one flat float64 vector: each layer's weight (inputs x outputs, row-major)
    then its bias."""

    def __init__(self, policy):
        import torch.nn as nn
        hidden = list(policy.mlp_extractor.policy_net)
        linear = [m for m in hidden if isinstance(m, nn.Linear)]
        if any(not isinstance(m, (nn.Linear, nn.Tanh)) for m in hidden) or len(hidden) != 2 * len(linear):
            raise ValueError(f"evolution strategies need a Linear/Tanh actor, not {hidden}")
        self.layers = [*linear, policy.action_net]
        self.shapes = [(layer.in_features, layer.out_features) for layer in self.layers]
        self.size = sum(i * o + o for i, o in self.shapes)

    def get(self) -> np.ndarray:
        return np.concatenate([np.concatenate([layer.weight.detach().numpy().T.ravel(), layer.bias.detach().numpy()])
                               for layer in self.layers]).astype(np.float64)

    def set(self, theta: np.ndarray) -> None:
        import torch
        with torch.no_grad():
            for layer, (weight, bias) in zip(self.layers, self.unflatten(theta[None, :])):
                layer.weight.copy_(torch.as_tensor(weight[0].T, dtype=layer.weight.dtype))
                layer.bias.copy_(torch.as_tensor(bias[0], dtype=layer.bias.dtype))

    def unflatten(self, thetas: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """(P, size) parameter vectors -> per layer (weights (P, inputs, outputs), biases (P, outputs))."""
        out, k = [], 0
        for i, o in self.shapes:
            weight = thetas[:, k:k + i * o].reshape(-1, i, o)
            k += i * o
            out.append((weight, thetas[:, k:k + o]))
            k += o
        return out


def actor_outputs(layers: list[tuple[np.ndarray, np.ndarray]], inputs: np.ndarray, xp=np) -> np.ndarray:
    """The P actors' outputs (P, B) for their (P, B, inputs) inputs: tanh hidden layers, linear last layer
    (the mean action, before the [-1, 1] clip), as SB3's deterministic ``predict``. ``xp``: numpy, or jax.numpy
    (:mod:`.jax_evolution`, under ``jit``)."""
    h = inputs
    for j, (weight, bias) in enumerate(layers):
        h = h @ weight + bias[:, None, :]
        if j < len(layers) - 1:
            h = xp.tanh(h)
    return h[..., 0]


class Population:
    """P candidate actors on P x B fields: candidate p acts on fields p B .. (p + 1) B - 1, each field seen through
    one :class:`~.agent.AgentInterface` (as a loaded policy's)."""

    def __init__(self, actor: ActorVector, thetas: np.ndarray, fields_each: int, interface: AgentInterface):
        self.layers = actor.unflatten(np.atleast_2d(thetas))
        self.fields_each = int(fields_each)
        self.interface = interface

    def reset(self, seed: int | None = None) -> None:
        self.interface.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        inputs, _ = self.interface.observe(obs)
        candidates = self.layers[0][0].shape[0]
        outputs = actor_outputs(self.layers, inputs.reshape(candidates, self.fields_each, -1).astype(np.float64))
        return self.interface.to_mm(outputs.reshape(-1, 1))


def centred_ranks(values: np.ndarray) -> np.ndarray:
    """Ranks of ``values`` scaled to [-0.5, 0.5], tied values sharing their mean rank (candidates whose
    perturbations change nothing, e.g. every action above the pivot's capacity, then add nothing to the
    gradient): the fitness shaping of Salimans et al."""
    values = np.asarray(values, dtype=float)
    distinct, group, count = np.unique(values, return_inverse=True, return_counts=True)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    mean_rank = first + (count - 1) / 2.0
    return mean_rank[group] / max(1, len(values) - 1) - 0.5


def antithetic_gradient(fitness: np.ndarray, noise: np.ndarray, noise_std: float) -> np.ndarray:
    """The ES gradient estimate from the fitness of the 2n candidates theta + sigma eps_i (first n) and
    theta - sigma eps_i (last n), ``noise`` (n, size) holding eps_i: centred ranks, antithetic differences."""
    n = len(noise)
    shaped = centred_ranks(np.asarray(fitness, dtype=float))
    return (shaped[:n] - shaped[n:]) @ noise / (2 * n * noise_std)


@dataclass
class Adam:
    """Adam's step (Kingma & Ba 2015) for gradient *ascent* on a flat parameter vector."""

    size: int
    beta1: float = 0.9
    beta2: float = 0.999
    epsilon: float = 1e-8

    def __post_init__(self):
        self.m = np.zeros(self.size)
        self.v = np.zeros(self.size)
        self.t = 0

    def step(self, gradient: np.ndarray, learning_rate: float) -> np.ndarray:
        self.t += 1
        self.m = self.beta1 * self.m + (1 - self.beta1) * gradient
        self.v = self.beta2 * self.v + (1 - self.beta2) * gradient ** 2
        m_hat = self.m / (1 - self.beta1 ** self.t)
        v_hat = self.v / (1 - self.beta2 ** self.t)
        return learning_rate * m_hat / (np.sqrt(v_hat) + self.epsilon)


class CheckpointSchedule:
    """When a learner with its own loop (evolution strategies, :mod:`.grpo`) checkpoints: ``checkpoint(0, early=
    False)`` at once; then, after each iteration (:meth:`after`), ``publish()`` (the current actor into the policy
    container) and ``checkpoint(steps, early=True)`` at the first iteration past 1 % of ``settings.timesteps``, and
    ``publish()`` and ``checkpoint(steps, early=False)`` every ``settings.eval_freq`` field-days before the end (the
    caller checkpoints the end)."""

    def __init__(self, settings, checkpoint, publish):
        self.timesteps, self.eval_freq = settings.timesteps, settings.eval_freq
        self.early_at = max(1, settings.timesteps // 100)
        self.next_eval, self.early_done = settings.eval_freq, False
        self.checkpoint, self.publish = checkpoint, publish
        checkpoint(0, early=False)

    def after(self, steps: int) -> None:
        if not self.early_done and steps >= self.early_at:
            self.early_done = True
            self.publish()
            self.checkpoint(steps, early=True)
        if steps >= self.next_eval and steps < self.timesteps:
            self.next_eval += self.eval_freq
            self.publish()
            self.checkpoint(steps, early=False)


# The second word of the seed of a run's generator of generations (seasons, terms; numpy ES: also the noise)
GENERATIONS_STREAM = 4_373


def generation_seasons(rng: np.random.Generator, scenario, seasons_each: int) -> tuple[np.ndarray, dict]:
    """A generation's ``seasons_each`` training seasons (indices into ``scenario``'s pool, without replacement)
    and their episode terms (name -> (seasons_each,) arrays), from ``rng``: what every candidate runs."""
    from ..policies.rollout import draw_terms
    seasons = rng.choice(scenario.n_seasons, seasons_each, replace=False)  # (train_task refused more than the pool)
    return seasons, draw_terms(scenario, seasons, int(rng.integers(2 ** 31)))


def candidates_episodes(actor: ActorVector, candidates: np.ndarray, interface: AgentInterface, scenario,
                        seasons: np.ndarray, terms: dict, seed: int):
    """Every candidate (rows of ``candidates``) on every one of ``seasons`` with ``terms``, all at once, the
    observation noise one stream from ``seed``: the :class:`~crop_agent_ros.policies.rollout.Episodes` of
    candidate p's fields p S .. (p + 1) S - 1."""
    from ..policies.rollout import run_episodes
    population = Population(actor, candidates, len(seasons), interface)
    return run_episodes(population, scenario, np.tile(seasons, len(candidates)), seed=seed,
                        terms={k: np.tile(v, len(candidates)) for k, v in terms.items()})


def learning_rate_at(settings, steps: int) -> float:
    """The step size after ``steps`` field-days: linear from ``learning_rate`` to ``final_learning_rate`` over
    ``timesteps``, then constant."""
    done = min(1.0, steps / settings.timesteps)
    return settings.learning_rate + (settings.final_learning_rate - settings.learning_rate) * done


def generation(actor: ActorVector, theta: np.ndarray, adam: Adam, rng: np.random.Generator,
               interface: AgentInterface, scenario, settings, steps: int) -> tuple[np.ndarray, int]:
    """One generation from ``theta`` after ``steps`` field-days, every draw from ``rng``: (the new parameters,
    the field-days it ran)."""
    pairs, noise_std = settings.pairs, settings.noise_std
    seasons, terms = generation_seasons(rng, scenario, settings.seasons)
    noise = rng.standard_normal((pairs, actor.size))
    candidates = np.concatenate([theta + noise_std * noise, theta - noise_std * noise])
    episodes = candidates_episodes(actor, candidates, interface, scenario, seasons, terms,
                                   seed=int(rng.integers(2 ** 31)))
    fitness = episodes.episode_return.reshape(len(candidates), settings.seasons).mean(axis=1)
    theta = theta + adam.step(antithetic_gradient(fitness, noise, noise_std), learning_rate_at(settings, steps))
    return theta, int(episodes.days.sum())


def evolve(model, interface: AgentInterface, scenario, settings, seed: int, checkpoint) -> int:
    """Run ES on ``model``'s actor for ``settings.timesteps`` field-days of ``scenario``'s training seasons (at most
    one generation more); ``checkpoint(steps, early)`` is called with the current parameters in ``model`` at the
    start, at the first generation past 1 % of the budget (``early`` True), and then every ``settings.eval_freq``
    field-days; the caller checkpoints the end. Returns the field-days run, with the final parameters in
    ``model``."""
    actor = ActorVector(model.policy)
    theta = actor.get()
    adam = Adam(actor.size)
    rng = np.random.default_rng([seed, GENERATIONS_STREAM])
    steps = 0
    schedule = CheckpointSchedule(settings, checkpoint, lambda: actor.set(theta))
    while steps < settings.timesteps:
        theta, days = generation(actor, theta, adam, rng, interface, scenario, settings, steps)
        steps += days
        schedule.after(steps)
    actor.set(theta)
    return steps
