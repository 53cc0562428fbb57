"""``crop-sim train --task TASK --algorithm ppo|es|grpo`` on a family task: PPO (Stable-Baselines3), evolution
strategies (:mod:`.evolution`; with the recipe's ``backend: jax``, :mod:`.jax_evolution`) or PPO with
group-relative advantages (:mod:`.grpo`), on the task's training seasons (generated weather only; the held-out
real seasons and the held-out climate are never seen). The settings are the recipe of :mod:`.hyperparameters`.

The network's observation and action are those of :mod:`crop_agent_ros.policies.learned` (normalised raw
observation, action in mm; ``paw_filter``: also a soil-water filter's PAW estimate; ``residual``: the action
corrects the task's tuned paced rule, whose proposal the network also sees, and training starts at the rule
(:func:`start_at_rule`); ``weather_inputs`` false: the climate's columns at their training mean). Training reward of PPO:
the task's reward (USD/ha) divided by ``REWARD_SCALE_USD`` and shaped by a potential (Ng et al. 1999),
Phi(s) = the value of the yield the crop would give if harvested now (tuber price / dry-matter fraction x
harvest index x true biomass), 0 at the season's end: the yield paid at harvest is spread over the days that
grew it; the optimal policy is unchanged, and every evaluation uses the true reward.

Along the way (every ``eval_freq`` field-days) the deterministic policy runs on fixed validation seasons (a
generator seed the training pool does not use) with fixed terms and is saved as ``checkpoint_<steps>.zip``
(the evaluation's learning curves on held-out seasons read them); the curve (CSV), a checkpoint at 1 % of
the budget (``early_model.zip``, for the "learning is real" check), the final policy (``final_model.zip``) and
the run's policy (``model.zip`` + ``model.json``: the checkpoint with the best validation return, as
:func:`select_model` picks it) go to the run's folder with ``summary.json``. Nothing held out is used to choose
anything.
"""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from crop_sim_ros.output import output_directory, replace_atomically, write_csv_atomic, write_json_atomic

from ..policies.learned import ACTION_SCALE_MM, RESIDUAL_SPAN_MM, AgentInterface, ObservationScaler
from .training_support import silent_logger, validation_scenario

REWARD_SCALE_USD = 1000.0
TRAINING_KINDS = ("generator", "mixture")
# The exploration log std saved in an ES agent's PPO container: ES never reads it (its candidates act
# deterministically); -2.5 is what the published agents' files hold.
ES_CONTAINER_LOG_STD = -2.5



def actor_container(input_size: int, policy_kwargs: dict, seed: int):
    """A fresh PPO policy that holds an ES or GRPO actor's network (PPO never learns; the learner sets its
    weights), for an observation of ``input_size`` values."""
    from stable_baselines3 import PPO
    from .agent import network_spaces
    return PPO("MlpPolicy", network_spaces(input_size), policy_kwargs=policy_kwargs, seed=seed, device="cpu",
               verbose=0)

def residual_rule(task: str):
    """The residual agent's rule: ``task``'s tuned paced rule (UsageError saying how to tune it if it has none)."""
    from crop_sim_ros.usage import UsageError
    from ..policies.family_tuning import tuned_rule
    try:
        return tuned_rule(task, "paced-rule")
    except (FileNotFoundError, ValueError) as error:
        raise UsageError(f"residual=true corrects the task's tuned paced rule: {error}") from None


def start_at_rule(policy) -> None:
    """Zero the actor's last layer (weights and bias): the residual agent's action is 0, the rule's own, for
    every input until training moves it."""
    import torch
    with torch.no_grad():
        policy.action_net.weight.zero_()
        policy.action_net.bias.zero_()


def action_record(interface: AgentInterface) -> dict:
    """What the run's ``model.json`` says of the action: its kind and mapping, and the residual's rule."""
    if interface.rule is None:
        return {"action_kind": "mm", "action": f"a in [-1, 1] -> (a + 1) / 2 x {ACTION_SCALE_MM:g} mm"}
    from ..policies.family_tuning import paced_rule_record
    return {"action_kind": "residual", "residual_rule": paced_rule_record(interface.rule),
            "action": f"a in [-1, 1] -> clip(paced rule's mm + a x {RESIDUAL_SPAN_MM:g}, 0, {ACTION_SCALE_MM:g}) mm"}


def fit_scaler(scenario, seed: int, seasons: int = 64) -> ObservationScaler:
    """Observation statistics over ``seasons`` training seasons under the default water-budget rule."""
    from crop_sim_ros.task import IrrigationVectorEnv
    from ..policies.family import FarmFacts, WaterBudgetRule

    rule = WaterBudgetRule(FarmFacts.of_scenario(scenario))
    env = IrrigationVectorEnv(seasons, scenario)
    obs, _ = env.reset(seed=seed + 17)
    seen = [obs]
    rule.reset(seed)
    for _ in range(160):
        obs, *_ = env.step(rule.act(obs))
        seen.append(obs)
    return ObservationScaler.fit(np.concatenate(seen))


def training_env(scenario, n_envs: int, seed: int, interface: AgentInterface, harvest_index: float,
                 dry_matter_fraction: float):
    """The SB3 VecEnv the network trains on (``interface``'s input in, [-1, 1] action out, scaled shaped
    reward)."""
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecEnvWrapper
    from crop_sim_ros.task.layout import EXTENDED
    from crop_sim_ros.task.sb3_vec import IrrigationSB3VecEnv

    price = EXTENDED.index("tuber_price_usd_per_t")

    class TaskWrapper(VecEnvWrapper):
        def __init__(self):
            super().__init__(IrrigationSB3VecEnv(n_envs, scenario, seed=seed),
                             observation_space=spaces.Box(-10.0, 10.0, (interface.input_size,), np.float32),
                             action_space=spaces.Box(-1.0, 1.0, (1,), np.float32))

        def _value_per_t(self, raw):
            return raw[:, price] / dry_matter_fraction

        def reset(self):
            raw = self.venv.reset()
            interface.reset()
            self.phi = np.zeros(self.num_envs)
            return interface.observe(raw)[0]

        def step_async(self, actions):
            self.venv.step_async(interface.to_mm(actions).reshape(-1, 1))

        def step_wait(self):
            raw, rewards, dones, infos = self.venv.step_wait()
            biomass = np.array([info["true_biomass_t_ha"] for info in infos])
            phi = np.where(dones, 0.0, self._value_per_t(raw) * harvest_index * biomass)
            shaped = (rewards + phi - self.phi) / REWARD_SCALE_USD
            self.phi = phi
            # (a terminal observation is bootstrapped only when the weather ran out)
            terminal = {i: infos[i]["terminal_observation"] for i in np.flatnonzero(dones)
                        if "terminal_observation" in infos[i]}
            inputs, terminal_inputs = interface.observe(raw, terminal)
            for i, terminal_input in terminal_inputs.items():
                infos[i]["terminal_observation"] = terminal_input
            return inputs, shaped.astype(np.float32), dones, infos

    return TaskWrapper()


def select_model(out: Path) -> dict:
    """``model.zip`` (+ ``.json``) of the run in ``out``: its checkpoint with the best validation return
    (``learning_curve.csv``; validation seasons are generated with a seed the training pool does not use; no
    held-out season is involved). Returns which one was chosen."""
    import shutil
    with open(out / "learning_curve.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f)]
    best = max(rows, key=lambda r: float(r["validation_return"]))
    steps = int(best["timesteps"])
    source = out / f"checkpoint_{steps:09d}.zip"
    if not source.exists():  # the last evaluation is the final model's
        source = out / "final_model.zip"
    replace_atomically(out / "model.zip", lambda temporary: shutil.copyfile(source, temporary))
    config = json.loads(source.with_suffix(".json").read_text())
    config["selected_by"] = "best validation return of the run's checkpoints (generated seasons, unused seed)"
    write_json_atomic(out / "model.json", config)
    return {"timesteps": steps, "validation_return": float(best["validation_return"]), "file": source.name}


def jax_evolution_learner():
    """The JAX ES learner (:mod:`.jax_evolution`), imported when asked for (it imports jax and evosax)."""
    try:
        from .jax_evolution import evolve_jax as learner
    except ImportError as error:
        from crop_sim_ros.usage import UsageError
        raise UsageError(f"es backend jax needs JAX and evosax (pip install crop_sim_ros[jax]): {error}") from None
    return learner


def train_task(scenario, algorithm: str, seed: int, out: Path, settings, progress: bool = True) -> dict:
    """Train ``algorithm`` on the family task ``scenario`` with ``settings`` (its recipe, validated by
    :mod:`.hyperparameters`); writes the run to ``out`` and returns its summary."""
    import torch
    from crop_sim_ros.task import core
    from crop_sim_ros.usage import UsageError
    from ..policies.family import FarmFacts, SoilWaterFilter, WaterBudgetRule
    from ..policies.family_tuning import draw_terms
    from ..policies.rollout import run_episodes
    from ..policies.learned import LearnedPolicy

    torch.set_num_threads(1)
    launched = time.perf_counter()
    if scenario.weather.kind not in TRAINING_KINDS:
        raise UsageError(f"refusing to train on {scenario.name!r}: training uses generated seasons only (real "
                         "seasons and the held-out climate are for evaluation)")
    out = output_directory(out)
    params = core.task_params(scenario)
    scaler = fit_scaler(scenario, seed)
    net_arch = list(settings.net_arch)
    paw_filter = None
    if settings.paw_filter:
        # the sensor's stated error is the task's PAW noise (a farmer knows the probe's specification)
        paw_filter = SoilWaterFilter(FarmFacts.of_scenario(scenario).capacity_mm, scenario.noise.paw_mm)
    interface = AgentInterface(scaler, paw_filter, residual_rule(scenario.name) if settings.residual else None,
                               settings.weather_inputs)
    from stable_baselines3 import PPO
    policy_kwargs = {"net_arch": net_arch, "log_std_init": settings.log_std_init if algorithm != "es" else ES_CONTAINER_LOG_STD}
    if algorithm == "ppo":
        venv = training_env(scenario, settings.n_envs, seed, interface, float(params.fields.harvest_index[0]),
                            params.dry_matter_fraction)
        lr0, lr1 = settings.learning_rate, settings.final_learning_rate
        model = PPO("MlpPolicy", venv, learning_rate=lambda progress_left: lr1 + (lr0 - lr1) * progress_left,
                    n_steps=settings.n_steps, batch_size=settings.batch_size, n_epochs=settings.n_epochs,
                    gamma=settings.gamma, gae_lambda=settings.gae_lambda, clip_range=settings.clip_range,
                    ent_coef=settings.ent_coef, policy_kwargs=policy_kwargs, seed=seed, device="cpu", verbose=0)
    else:  # es, grpo: they run their own seasons
        model = actor_container(interface.input_size, policy_kwargs, seed)
    if settings.residual:
        start_at_rule(model.policy)
    model.set_logger(silent_logger())
    validation = validation_scenario(scenario, settings.validation_seasons, seed)
    seasons = np.arange(settings.validation_seasons)
    terms = draw_terms(validation, seasons, 1234)
    default_rule = WaterBudgetRule(FarmFacts.of_scenario(scenario))
    rule_return = float(run_episodes(default_rule, validation, seasons, seed=1000, terms=terms).episode_return.mean())
    config = {"task": scenario.name, "algorithm": algorithm, "history": 1, "seed": seed,
              "timesteps": settings.timesteps, "training_seasons": scenario.n_seasons, "net_arch": net_arch,
              **action_record(interface), "weather_inputs": interface.weather_inputs,
              **({} if paw_filter is None else {"paw_filter": paw_filter.record()}),
              "scaler": scaler.record(),
              "reward": f"task reward USD/ha / {REWARD_SCALE_USD:g} + potential shaping (value of the yield so far)",
              "hyper_parameters": settings.record()}

    def save(model_, name: str, at: int) -> Path:
        path = replace_atomically(out / f"{name}.zip", model_.save)
        write_json_atomic(path.with_suffix(".json"), {**config, "timesteps_at_save": at})
        return path

    rows: list[dict] = []
    started: float | None = None  # when training started (training_starts)

    def checkpoint(model_, steps: int) -> None:
        """Save the policy as ``checkpoint_<steps>`` and add its validation row to the curve."""
        path = save(model_, f"checkpoint_{steps:09d}", steps)
        episodes = run_episodes(LearnedPolicy(path), validation, seasons, seed=1000, terms=terms)
        row = {"timesteps": int(steps), "wall_s": round(time.perf_counter() - started, 1),
               "validation_return": float(episodes.episode_return.mean()),
               "validation_minus_default_rule": float(episodes.episode_return.mean() - rule_return),
               "validation_water_mm": float(episodes.water_mm.mean())}
        rows.append(row)
        print(f"[{row['timesteps']:>9}] {row['wall_s']:>6.0f} s  validation return {row['validation_return']:.1f}"
              f" (default rule {rule_return:.1f}), water {row['validation_water_mm']:.0f} mm",
              file=sys.stderr, flush=True)

    def training_starts() -> None:
        nonlocal started
        started = time.perf_counter()
        print(f"training starts {started - launched:.1f} s after launch", file=sys.stderr, flush=True)

    if algorithm == "ppo":
        from stable_baselines3.common.callbacks import BaseCallback
        early_at = max(settings.n_envs * settings.n_steps, settings.timesteps // 100)

        class Curve(BaseCallback):
            def __init__(self):
                super().__init__()
                self.next_eval = 0
                self.early_saved = False

            def _on_training_start(self) -> None:
                training_starts()

            def _on_step(self) -> bool:
                if not self.early_saved and self.num_timesteps >= early_at:
                    self.early_saved = True
                    save(self.model, "early_model", self.num_timesteps)
                    checkpoint(self.model, self.num_timesteps)
                if self.num_timesteps >= self.next_eval:
                    self.next_eval += settings.eval_freq
                    checkpoint(self.model, self.num_timesteps)
                return True

        model.learn(total_timesteps=settings.timesteps, callback=Curve(), progress_bar=progress)
        steps_run = int(model.num_timesteps)
    else:
        from .evolution import evolve
        from .grpo import grpo

        def own_loop_checkpoint(steps: int, early: bool) -> None:
            if early:
                save(model, "early_model", steps)
            checkpoint(model, steps)

        training_starts()
        learner = grpo if algorithm == "grpo" else evolve if settings.backend == "numpy" else jax_evolution_learner()
        steps_run = learner(model, interface, scenario, settings, seed, own_loop_checkpoint)
    training_s = time.perf_counter() - started
    checkpoint(model, steps_run)
    save(model, "final_model", steps_run)
    write_csv_atomic(out / "learning_curve.csv", list(rows[0]), rows)
    selected = select_model(out)
    summary = {**config, "steps_run": steps_run, "selected": selected, "training_wall_s": round(training_s, 1),
               "total_wall_s": round(time.perf_counter() - launched, 1), "default_rule_validation_return": rule_return,
               "final": rows[-1], "command": "crop-sim " + " ".join(sys.argv[1:])}
    write_json_atomic(out / "summary.json", summary)   # last: a run with a summary is a finished run
    print(f"ran {steps_run} steps ({settings.timesteps} asked) in {training_s:.0f} s of training, "
          f"{summary['total_wall_s']:.0f} s in all; wrote {out}", file=sys.stderr)
    return summary
