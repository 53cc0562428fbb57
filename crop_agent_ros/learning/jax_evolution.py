"""Evolution strategies on JAX: the recipe of :mod:`.evolution` with evosax's OpenAI-ES, a whole generation
(candidates drawn, every candidate on every season, the update) in one jitted call.

Selected by the ES recipe's ``backend`` key: ``crop-sim train --task T --algorithm es --hyperparams backend=jax``
(``hyperparams/es.yml``: ``backend: numpy``, the published agents' learner, is the default). The same recipe as
the numpy learner, setting for setting:

- a generation draws ``seasons`` training seasons of the task's pool and their episode terms from the same
  numpy generator as :func:`~.evolution.evolve` (:func:`~.evolution.generation_seasons`: common random numbers,
  every candidate runs the same seasons with the same terms); the observation noise is common too: every
  candidate sees season s with the same noise (the numpy learner draws it per field; see
  :meth:`PopulationRollout._noise` for why);
- ``pairs`` antithetic candidates theta +- ``noise_std`` x eps_i (evosax ``Open_ES``, antithetic sampling), each
  a deterministic network (the same architecture, observation scaling and action in mm as the loaded agent,
  :mod:`crop_agent_ros.policies.learned`; float32, as the exported network runs) acting on every field-day of
  the JAX environment (:mod:`crop_sim_ros.task.jax_env`, float64: the numpy environment's numbers);
- fitness: the candidate's mean season return (USD/ha, the task's reward), shaped by centred ranks (ties sharing
  their mean rank); the antithetic estimate moves theta by Adam (optax, the numpy learner's constants), its step
  size linear from ``learning_rate`` to ``final_learning_rate`` over ``timesteps`` field-days
  (:func:`~.evolution.learning_rate_at`); evosax minimises, so it is told the negated returns (the same update:
  centred ranks are odd in the fitness, Adam's step odd in the gradient);
- checkpoints, validation and the run's files are :mod:`.train_task`'s: the actor is copied into the PPO policy
  container (model.zip + model.json) that ``crop-sim evaluate``, the agent node and
  :class:`~crop_agent_ros.policies.learned.LearnedPolicy` load; ``algorithm`` stays ``es``, the recorded
  ``hyper_parameters`` say ``backend: jax``.

What differs from the numpy learner is the random streams (the parameter noise and the observation noise come
from JAX keys of the seed) and the common observation noise, so a seed gives another run than ``backend: numpy``,
the same run every time on one machine. No soil-water filter (``paw_filter``: refused by the recipe).

On a CPU the population is split over one XLA device per CPU the process may use (:func:`use_host_cpus`,
:func:`candidates_split`): each part's fields run on their own thread, with the same returns as on one device.

This module imports jax, optax and evosax (``pip install crop_sim_ros[jax]``); nothing imports it unless asked.
"""

from __future__ import annotations

import os
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from crop_sim_ros.task import core
from crop_sim_ros.task.jax_env import JaxIrrigationEnv

from ..policies.learned import ACTION_SCALE_MM, AgentInterface
from .evolution import (GENERATIONS_STREAM, ActorVector, Adam, CheckpointSchedule, actor_outputs, generation_seasons,
                        learning_rate_at)

# The network's float type (the exported policy runs in float32, in PyTorch)
NETWORK_DTYPE = jnp.float32
# Adam's constants: the numpy learner's
ADAM = {"b1": Adam.beta1, "b2": Adam.beta2, "eps": Adam.epsilon}


class PopulationRollout:
    """P candidate networks (flat parameter vectors in ``actor``'s layout, :class:`~.evolution.ActorVector`)
    each on the same S seasons of ``scenario``'s pool: P x S fields of the JAX environment run whole seasons
    together, until every field's season ended (``jax.lax.while_loop`` over the days, ``jax.vmap`` over the
    fields). Build it and call it under ``jax.enable_x64(True)`` for float64."""

    def __init__(self, scenario, interface: AgentInterface, actor: ActorVector):
        if interface.paw_filter is not None or interface.rule is not None or not interface.weather_inputs:
            raise ValueError("the JAX rollout has no soil-water filter and no paced rule, and sees every input")
        self.env = JaxIrrigationEnv(scenario, table=core.scenario_table(scenario))
        self.params = self.env.default_params
        self.actor = actor
        self.mean = jnp.asarray(interface.scaler.mean)
        self.std = jnp.asarray(interface.scaler.std)

    def irrigation_mm(self, layers, obs: jax.Array, candidates: int) -> jax.Array:
        """The day's irrigation (N,) mm of the N = P x S fields' (N, 29) observations: scaled as
        :class:`~crop_agent_ros.policies.learned.ObservationScaler` (float64), each candidate's network on its
        fields, a in [-1, 1] -> (a + 1) / 2 x ACTION_SCALE_MM mm."""
        scaled = jnp.clip((obs - self.mean) / self.std, -10.0, 10.0).astype(NETWORK_DTYPE)
        outputs = actor_outputs(layers, scaled.reshape(candidates, -1, scaled.shape[-1]), xp=jnp)
        return ((jnp.clip(outputs, -1.0, 1.0) + 1.0) * 0.5 * ACTION_SCALE_MM).reshape(-1)

    def _noise(self, key: jax.Array, candidates: int, seasons: int) -> jax.Array:
        """One day's observation noise of every field, common to the candidates (zeros for a task without noise:
        nothing to draw): one draw per season, candidate p's field of season s gets season s's. Why common: the
        candidates then differ by their networks alone (common random numbers, as for the seasons and terms), and
        the normal draws, per field, cost more on a CPU than the environment's day."""
        shape = (seasons, self.env.task.noise_columns)
        noise = jax.random.normal(key, shape, jnp.float32) if self.env.task.noisy else jnp.zeros(shape, jnp.float32)
        return jnp.tile(noise, (candidates, 1))

    def __call__(self, thetas: jax.Array, seasons: jax.Array, terms: core.EpisodeTerms, key: jax.Array):
        """Season returns (P, S) (USD/ha) and days run (P, S) of candidate p on season s (pool indices
        ``seasons`` (S,), episode terms ``terms`` of (S,) arrays), the observation noise from ``key``."""
        candidates, count = thetas.shape[0], seasons.shape[0]
        layers = self.actor.unflatten(thetas.astype(NETWORK_DTYPE))
        field_terms = core.EpisodeTerms(*(jnp.tile(jnp.asarray(t), candidates) for t in terms))
        key, first = jax.random.split(key)
        obs, state = jax.vmap(self.env.reset_with, in_axes=(0, 0, 0, None))(
            jnp.tile(seasons, candidates), field_terms, self._noise(first, candidates, count), self.params)
        step = jax.vmap(self.env.step_with, in_axes=(0, 0, 0, None))

        def day(carry):
            key, obs, state, alive, total, days = carry
            key, sub = jax.random.split(key)
            obs, state, reward, terminated, truncated, _ = step(
                state, self.irrigation_mm(layers, obs, candidates), self._noise(sub, candidates, count), self.params)
            total = total + jnp.where(alive, reward, 0.0)
            return key, obs, state, alive & ~(terminated | truncated), total, days + alive

        fields = candidates * count
        start = (key, obs, state, jnp.ones(fields, bool), jnp.zeros(fields), jnp.zeros(fields, jnp.int32))
        *_, total, days = jax.lax.while_loop(lambda carry: carry[3].any(), day, start)
        return total.reshape(candidates, -1), days.reshape(candidates, -1)


def open_es(settings, size: int):
    """evosax's OpenAI-ES of the recipe ``settings`` on ``size`` parameters: ``2 pairs`` candidates, antithetic,
    std ``noise_std``, centred ranks (its default fitness shaping), Adam whose step size :func:`tell` sets."""
    from evosax.algorithms import Open_ES  # imported here: importing evosax starts JAX's backend (use_host_cpus)
    return Open_ES(population_size=2 * settings.pairs, solution=jnp.zeros(size), use_antithetic_sampling=True,
                   optimizer=optax.inject_hyperparams(optax.adam)(learning_rate=settings.learning_rate, **ADAM),
                   std_schedule=optax.constant_schedule(settings.noise_std))


def tell(strategy, state, key: jax.Array, population: jax.Array, fitness: jax.Array, learning_rate):
    """``strategy``'s state after the candidates ``population`` (P, size) returned ``fitness`` (P,) (higher is
    better: evosax minimises, so it is told the negation), Adam's step size ``learning_rate``."""
    opt_state = state.opt_state
    state = state.replace(opt_state=opt_state._replace(
        hyperparams={**opt_state.hyperparams, "learning_rate": jnp.asarray(learning_rate)}))
    state, _ = strategy.tell(key, population, -fitness, state, strategy.default_params)
    return _strongly_typed(state)


def use_host_cpus() -> None:
    """Ask XLA's CPU backend for one device per CPU this process may run on, so that :func:`candidates_split`
    can run the population's parts side by side (XLA runs one device's program on one thread, and a field-day's
    operations are too small to spread over threads). Only before JAX's first operation: afterwards the backend
    keeps the devices it started with (then nothing changes)."""
    try:
        jax.config.update("jax_num_cpu_devices", len(os.sched_getaffinity(0)))
    except RuntimeError:
        pass


def candidates_split(rollout: PopulationRollout, candidates: int):
    """(``rollout`` with the candidates split evenly over the default backend's devices, the number of parts): as
    many parts as divide ``candidates`` (``jax.shard_map``), each part's seasons run on its own device until its
    own fields end. The same returns as on one device: a candidate's fields depend on its network and the common
    draws only."""
    devices = jax.devices()
    parts = max(n for n in range(1, len(devices) + 1) if candidates % n == 0)
    if parts == 1:
        return rollout, 1
    mesh = jax.sharding.Mesh(np.array(devices[:parts]), ("candidates",))
    split, whole = jax.sharding.PartitionSpec("candidates"), jax.sharding.PartitionSpec()
    return jax.shard_map(rollout, mesh=mesh, in_specs=(split, whole, whole, whole), out_specs=(split, split),
                         check_vma=False), parts  # the per-part loops use no collectives


class JaxEvolution:
    """The ES learner on JAX: evosax's ``Open_ES`` (:func:`open_es`) over a :class:`PopulationRollout`;
    :meth:`generation` is one jitted call."""

    def __init__(self, scenario, interface: AgentInterface, actor: ActorVector, settings):
        use_host_cpus()
        self.rollout, self.parts = candidates_split(PopulationRollout(scenario, interface, actor), 2 * settings.pairs)
        self.strategy = open_es(settings, actor.size)
        self._generation = jax.jit(self._generation_of)

    def start(self, theta: np.ndarray, key: jax.Array):
        """evosax's state with the mean ``theta`` (the network's initial parameters)."""
        return _strongly_typed(self.strategy.init(key, jnp.asarray(theta), self.strategy.default_params))

    def _generation_of(self, state, key, seasons, terms, learning_rate):
        key_ask, key_rollout, key_tell = jax.random.split(key, 3)
        population, state = self.strategy.ask(key_ask, state, self.strategy.default_params)
        returns, days = self.rollout(population, seasons, terms, key_rollout)
        fitness = returns.mean(axis=1)
        return tell(self.strategy, state, key_tell, population, fitness, learning_rate), fitness, days.sum()

    def generation(self, state, key: jax.Array, seasons: np.ndarray, terms: dict, learning_rate: float):
        """One generation on ``seasons`` with ``terms`` (name -> (S,) arrays) and Adam's step ``learning_rate``:
        (the new state, the candidates' fitness (2 pairs,) USD/ha, the field-days run)."""
        state, fitness, days = self._generation(state, key, jnp.asarray(seasons), core.EpisodeTerms(**terms),
                                                learning_rate)
        return state, fitness, int(days)

    def theta(self, state) -> np.ndarray:
        """The mean of the search distribution (the network's parameters), float64."""
        return np.array(state.mean, dtype=np.float64)  # a writable copy (torch warns on a read-only array)


def _strongly_typed(state):
    """``state`` with every leaf strongly typed: evosax's ``init`` and ``tell`` leave some weakly typed, and a
    jitted generation given a state of other types compiles again."""
    return jax.tree.map(lambda leaf: jnp.asarray(leaf, dtype=leaf.dtype), state)


def generation_key(seed: int, generation: int) -> jax.Array:
    """The JAX key of generation ``generation`` of a run of seed ``seed`` (parameter and observation noise)."""
    return jax.random.fold_in(jax.random.key(seed), generation)


def evolve_jax(model, interface: AgentInterface, scenario, settings, seed: int, checkpoint) -> int:
    """:func:`~.evolution.evolve` on JAX (same arguments, same checkpoints and return): ES on ``model``'s actor
    for ``settings.timesteps`` field-days (at most one generation more); the final parameters in ``model``. Prints
    (stderr) the generations' wall time apart from the checkpoints' (validation on the host, numpy)."""
    actor = ActorVector(model.policy)
    clock = {"checkpoints_s": 0.0}

    def timed_checkpoint(steps: int, early: bool) -> None:
        start = time.perf_counter()
        checkpoint(steps, early)
        clock["checkpoints_s"] += time.perf_counter() - start

    started = time.perf_counter()
    with jax.enable_x64(True):
        learner = JaxEvolution(scenario, interface, actor, settings)
        state = learner.start(actor.get(), jax.random.key(seed))
        rng = np.random.default_rng([seed, GENERATIONS_STREAM])
        steps, generation = 0, 0
        schedule = CheckpointSchedule(settings, timed_checkpoint, lambda: actor.set(learner.theta(state)))
        while steps < settings.timesteps:
            seasons, terms = generation_seasons(rng, scenario, settings.seasons)
            state, _, days = learner.generation(state, generation_key(seed, generation), seasons, terms,
                                                learning_rate_at(settings, steps))
            if generation == 0:
                clock["first_s"] = time.perf_counter() - started - clock["checkpoints_s"]
            steps += days
            generation += 1
            schedule.after(steps)
        actor.set(learner.theta(state))
    loop_s = time.perf_counter() - started - clock["checkpoints_s"]
    print(f"JAX ES on {jax.devices()[0].platform}: {generation} generations, {steps:,} field-days in {loop_s:.1f} s "
          f"of ES ({clock['first_s']:.1f} s to the end of the first generation, compilation included; "
          f"{steps / loop_s:,.0f} field-days/s, candidates split over {learner.parts} devices), "
          f"{clock['checkpoints_s']:.1f} s of checkpoints",
          file=sys.stderr, flush=True)
    return steps
