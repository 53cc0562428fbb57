"""PPO (Stable-Baselines3) on the paper's task: ``crop-sim train --task benton-generated --algorithm ppo``.

Training runs on the batched task environment (``crop_sim_ros.task.sb3_vec``) of a generated-weather scenario
(the real held-out seasons are refused). The network sees the fixed features of
:mod:`crop_agent_ros.policies.sb3` and acts through its action mapping (``action_mode: margin``: the safety
margin, mm, above the day's estimated no-stress water level); the training reward is the task's reward with
potential-based shaping by the crop's yield so far (``reward_shaping``; evaluation always uses the true
reward). Every ``eval_freq`` field-days the deterministic policy runs on (a) fresh generated validation seasons
(a generator seed the training pool does not use; ``best_validation_model.zip`` keeps the best) and (b) the
held-out real seasons, whose regret against the hindsight oracle is only reported, never used to choose anything
(so the oracle is planned after training, and the progress lines show the held-out return minus the refill
rule's; the learning curve has the regrets). Before training starts it prints how long after launch that was,
and the wall and CPU time of each part of the start-up. The shaping reads each field's true biomass from the
batched environment's state (the SB3 adapter does not pass it in ``infos``).

Writes to the run's folder: ``model.zip`` with ``model.json`` (the policy's feature and action settings, read by
the loader), ``learning_curve.csv`` and ``.png``, and ``config.json`` (seed, scenario, hyperparameters, package
versions, the steps that ran (whole rollouts: at least ``timesteps``), training, evaluation and start-up
times). The shipped ``crop_agent_ros/policies/ppo_benton.zip`` is this run's ``model.zip`` with the recipe's
defaults and seed 0.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from crop_sim_ros.output import output_directory, replace_atomically, save_figure_atomic, write_csv_atomic, \
    write_json_atomic

from .training_support import package_versions, seconds_since_launch, silent_logger, validation_scenario

HELD_OUT = ("heldout", "benton-2000", "paterson-1992", "paterson-1993", "paterson-1994", "paterson-1995")
HELD_OUT_SCENARIO = "heldout"  # the real seasons whose regret the learning curve reports (never used to choose)


class PolicyOfModel:
    """A :class:`~crop_agent_ros.policies.base.Policy` view of a PPO model being trained."""

    def __init__(self, model, action_mode: str, feature_set: str = "full", mapping: dict | None = None,
                 name: str = "ppo"):
        self.model, self.action_mode, self.feature_set, self.name = model, action_mode, feature_set, name
        self.mapping = mapping or {}

    def reset(self, seed=None):
        pass

    def act(self, obs):
        from ..policies.sb3 import action_to_mm, features
        action, _ = self.model.predict(features(obs, self.feature_set), deterministic=True)
        return action_to_mm(action, obs, self.action_mode, **self.mapping)


def training_vec_env(scenario, n_envs: int, seed: int):
    """The task's SB3 VecEnv; its infos carry each field's true biomass for the reward shaping."""
    from crop_sim_ros.task.sb3_vec import IrrigationSB3VecEnv

    return IrrigationSB3VecEnv(n_envs, scenario, seed=seed)


def feature_action_wrapper(venv, action_mode: str, feature_set: str = "full", mapping: dict | None = None,
                           shaping: str = "none", gamma: float = 1.0,
                           harvest_index: float = 0.9, initial_biomass_t_ha: float = 0.001):
    """The SB3 VecEnv the network trains on: features in, [-1, 1] actions out (mapped to mm).

    ``shaping="biomass"``: potential-based shaping (Ng et al. 1999) with the potential
    Phi(s) = HI * true biomass (t/ha, the yield the crop would give if harvested now) and Phi = 0 at the
    end of a season: r' = r + gamma Phi(s') - Phi(s). The yield paid at harvest is spread over the days
    that grew it (a day of water stress costs at once); the optimal policy is unchanged and every
    evaluation uses the true reward."""
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecEnvWrapper
    from ..policies.sb3 import FEATURE_SETS, action_to_mm, features

    class FeatureActionWrapper(VecEnvWrapper):
        def __init__(self):
            super().__init__(venv, observation_space=spaces.Box(-10.0, 10.0, (FEATURE_SETS[feature_set],), np.float32),
                             action_space=spaces.Box(-1.0, 1.0, (1,), np.float32))
            self.raw = None

        def reset(self):
            self.raw = self.venv.reset()
            self.phi = np.full(self.num_envs, harvest_index * initial_biomass_t_ha)
            return features(self.raw, feature_set)

        def step_async(self, actions):
            self.venv.step_async(action_to_mm(actions, self.raw, action_mode, **(mapping or {})).reshape(-1, 1))

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            if shaping == "biomass":
                phi = harvest_index * np.array([info["true_biomass_t_ha"] for info in infos])
                rewards = (rewards + gamma * np.where(dones, 0.0, phi) - self.phi).astype(np.float32)
                self.phi = phi
            for i in np.flatnonzero(dones):
                if "terminal_observation" in infos[i]:
                    infos[i]["terminal_observation"] = features(infos[i]["terminal_observation"], feature_set)[0]
            self.raw = obs
            return features(obs, feature_set), rewards, dones, infos

    return FeatureActionWrapper()


def plot_curve(rows: list[dict], path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    steps = [r["timesteps"] for r in rows]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    axes[0].plot(steps, [r["heldout_normalized_return"] for r in rows], "o-", label="held-out (real seasons)")
    axes[0].plot(steps, [r["validation_normalized_return"] for r in rows], "s-", label="validation (generated)")
    for key, style, label in (("heldout_refill_normalized_return", "--", "refill rule, held-out"),):
        if rows and key in rows[0]:
            axes[0].axhline(rows[0][key], ls=style, color="gray", label=label)
    axes[0].set_xlabel("environment steps (field-days)")
    axes[0].set_ylabel("mean normalized return")
    axes[0].legend(fontsize=8)
    axes[1].semilogy(steps, [max(r["heldout_regret"], 1e-5) for r in rows], "o-", label="held-out regret")
    if rows and "heldout_refill_regret" in rows[0]:
        axes[1].axhline(rows[0]["heldout_refill_regret"], ls="--", color="gray", label="refill rule regret")
    axes[1].set_xlabel("environment steps (field-days)")
    axes[1].set_ylabel("oracle return - policy return, t/ha")
    axes[1].legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


def check_training_scenario(scenario) -> None:
    """UsageError unless ``scenario`` is generated weather (the real held-out seasons are never trained on)."""
    if scenario.name in HELD_OUT or scenario.weather.kind != "generator":
        from crop_sim_ros.usage import UsageError
        raise UsageError(f"refusing to train on {scenario.name!r}: training uses generated seasons only "
                         f"(held-out: {', '.join(HELD_OUT)})")


def train(task: str, seed: int, out: Path, settings, progress: bool = True) -> dict:
    """PPO on the paper's task ``task`` with ``settings`` (a :class:`~.hyperparameters.PaperPPO`); writes to ``out``
    (see the module docstring) and returns the run's record."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from ..policies.oracle import OraclePolicy
    from ..policies.rollout import run_episodes, scenario_of, season_contexts
    from ..policies.rules import tuned_refill_policy
    from ..policies.sb3 import FEATURE_SETS, FEATURE_VERSION

    torch.set_num_threads(1)
    # wall and CPU seconds of each part before training (a busy machine stretches wall time, not CPU time)
    startup = {"imports": (seconds_since_launch(), time.process_time())}
    mark = (time.perf_counter(), time.process_time())

    def phase(name: str) -> None:
        nonlocal mark
        now = (time.perf_counter(), time.process_time())
        startup[name] = (now[0] - mark[0], now[1] - mark[1])
        mark = now

    scenario = scenario_of(task)
    check_training_scenario(scenario)
    out = output_directory(out)
    net_arch = list(settings.net_arch)
    hyper = settings.record()

    # evaluation sets: held-out real seasons (reported only) and fresh generated validation seasons
    heldout = scenario_of(HELD_OUT_SCENARIO)
    heldout_contexts = season_contexts(heldout)
    validation = validation_scenario(scenario, settings.validation_seasons, seed)
    eval_seeds = list(range(1000, 1000 + settings.eval_seeds))
    refill = tuned_refill_policy()

    def score(policy, scen, contexts=None):
        seasons = np.arange(len(contexts) if contexts else settings.validation_seasons)
        runs = [run_episodes(policy, scen, seasons, seed=s, contexts=contexts) for s in eval_seeds]
        ret = np.mean([r.episode_return for r in runs], axis=0)
        norm = np.mean([r.normalized_return for r in runs], axis=0)
        return ret, norm, float(np.mean([r.water_mm for r in runs]))

    r_ref, n_ref, _ = score(refill, heldout, heldout_contexts)
    v_ref, _, _ = score(refill, validation)
    # the regrets need the held-out oracle, which chooses nothing: it is planned after training (see below)
    baseline = {"heldout_refill_return": float(r_ref.mean()), "heldout_refill_normalized_return": float(n_ref.mean()),
                "heldout_refill_regret": float("nan"), "validation_refill_return": float(v_ref.mean())}
    heldout_returns: list[np.ndarray] = []  # per evaluation, per held-out season
    phase("refill baselines")

    params = scenario.field_parameters()
    mapping = {"margin_center_mm": settings.margin_center_mm, "margin_span_mm": settings.margin_span_mm}
    if settings.action_mode == "demand":
        mapping["demand_span"] = settings.demand_span
    venv = feature_action_wrapper(training_vec_env(scenario, settings.n_envs, seed), settings.action_mode,
                                  settings.feature_set, mapping, settings.reward_shaping, settings.gamma, float(params.harvest_index[0]),
                                  float(params.initial_biomass_kg_ha[0]) / 1000.0)
    lr0, lr1 = settings.learning_rate, settings.final_learning_rate
    model = PPO("MlpPolicy", venv, learning_rate=lambda progress: lr1 + (lr0 - lr1) * progress,
                n_steps=settings.n_steps, batch_size=settings.batch_size, n_epochs=settings.n_epochs, gamma=settings.gamma,
                gae_lambda=settings.gae_lambda, clip_range=settings.clip_range, ent_coef=settings.ent_coef,
                policy_kwargs={"net_arch": net_arch, "log_std_init": settings.log_std_init}, seed=seed,
                device="cpu", verbose=0)
    model.set_logger(silent_logger())
    rows: list[dict] = []
    started = time.perf_counter()
    best = {"validation_return": -np.inf, "timesteps": 0}
    evaluation_s = [0.0]

    class Curve(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next_eval = 0
            self.episode_returns: list[float] = []

        def _on_training_start(self) -> None:
            phase("environments and model")
            parts = ", ".join(f"{name} {wall:.1f} s (CPU {cpu:.1f} s)" for name, (wall, cpu) in startup.items())
            startup["training started"] = (seconds_since_launch(), time.process_time())
            print(f"training started {startup['training started'][0]:.1f} s after launch, after "
                  f"{startup['training started'][1]:.1f} s of CPU: {parts}", file=sys.stderr, flush=True)

        def _on_step(self) -> bool:
            for info in self.locals.get("infos", []):
                if "episode_return" in info:
                    self.episode_returns.append(info["episode_return"])
            if self.num_timesteps >= self.next_eval:
                self.next_eval += settings.eval_freq
                self.evaluate()
            return True

        def _on_training_end(self) -> None:
            if not rows or rows[-1]["timesteps"] != self.num_timesteps:
                self.evaluate()

        def evaluate(self):
            evaluation_started = time.perf_counter()
            policy = PolicyOfModel(self.model, settings.action_mode, settings.feature_set, mapping)
            ret, norm, water = score(policy, heldout, heldout_contexts)
            vret, vnorm, _ = score(policy, validation)
            recent = self.episode_returns[-200:]
            row = {"timesteps": int(self.num_timesteps), "wall_s": round(time.perf_counter() - started, 1),
                   "train_episode_return": float(np.mean(recent)) if recent else float("nan"),
                   "validation_return": float(vret.mean()), "validation_normalized_return": float(vnorm.mean()),
                   "validation_minus_refill": float(vret.mean() - v_ref.mean()),
                   "heldout_return": float(ret.mean()), "heldout_normalized_return": float(norm.mean()),
                   "heldout_regret": float("nan"), "heldout_irrigation_mm": water, **baseline}
            rows.append(row)
            heldout_returns.append(ret)
            if vret.mean() > best["validation_return"]:
                best.update(validation_return=float(vret.mean()), timesteps=int(self.num_timesteps))
                replace_atomically(out / "best_validation_model.zip", self.model.save)
            print(f"[{row['timesteps']:>9}] {row['wall_s']:>7.1f} s  validation - refill "
                  f"{row['validation_minus_refill']:+.4f}  held-out - refill {ret.mean() - r_ref.mean():+.4f} t/ha",
                  file=sys.stderr, flush=True)
            evaluation_s[0] += time.perf_counter() - evaluation_started

    callback = Curve()
    model.learn(total_timesteps=settings.timesteps, callback=callback, progress_bar=progress)
    wall = time.perf_counter() - started
    steps_run = int(model.num_timesteps)  # whole rollouts of n_steps x n_envs: at least --timesteps
    replace_atomically(out / "model.zip", model.save)
    oracle_started = time.perf_counter()
    oracle = OraclePolicy()
    oracle.begin_season(heldout_contexts)
    heldout_oracle = np.array([r.return_value for r in oracle.results])
    oracle_s = time.perf_counter() - oracle_started
    for row, ret in zip(rows, heldout_returns):
        row.update(heldout_regret=float((heldout_oracle - ret).mean()),
                   heldout_refill_regret=float((heldout_oracle - r_ref).mean()))
    policy_config = {"action_mode": settings.action_mode, "feature_set": settings.feature_set, "action_mapping": mapping,
                     "feature_version": FEATURE_VERSION, "n_features": FEATURE_SETS[settings.feature_set],
                     "trained_on": scenario.name, "seed": seed, "timesteps": settings.timesteps,
                     "note": "deterministic actions; features and action mapping: crop_agent_ros.policies.sb3"}
    write_json_atomic(out / "model.json", policy_config, indent=2)
    if (out / "best_validation_model.zip").exists():
        write_json_atomic(out / "best_validation_model.json", {**policy_config, "timesteps_at_save": best["timesteps"]},
                          indent=2)
    write_csv_atomic(out / "learning_curve.csv", list(rows[0]), rows)
    plot_curve(rows, out / "learning_curve.png", f"PPO on {scenario.name}, seed {seed}")
    config = {"command": "crop-sim " + " ".join(sys.argv[1:]), "task": scenario.name, "algorithm": "ppo",
              "seed": seed, "scenario": scenario.name, "training_weather": {
                  "kind": scenario.weather.kind, "generator": scenario.weather.generator,
                  "seed": scenario.weather.seed, "n_seasons": scenario.weather.n_seasons},
              "validation_weather": {"generator_seed": validation.weather.seed, "n_seasons": settings.validation_seasons},
              "eval_scenario": heldout.name, "eval_noise_seeds": eval_seeds, "hyper_parameters": hyper,
              "reward": ("evaluation: the task's true reward (C_I * mm daily + yield t/ha at harvest); training: "
                         + ("the true reward" if settings.reward_shaping == "none" else
                            "plus potential-based shaping gamma*Phi(s') - Phi(s), Phi = HI * true biomass t/ha")),
              "policy": policy_config, "timesteps_run": steps_run, "wall_time_s": round(wall, 1),
              "training_time_s": round(wall - evaluation_s[0], 1), "evaluation_time_s": round(evaluation_s[0], 1),
              "heldout_oracle_time_s": round(oracle_s, 1),
              "evaluations": len(rows),
              "startup_wall_cpu_s": {name: [round(wall, 2), round(cpu, 2)] for name, (wall, cpu) in startup.items()},
              "torch_threads": torch.get_num_threads(),
              "best_validation": best, "final": rows[-1], "versions": package_versions()}
    write_json_atomic(out / "config.json", config, indent=2, default=str)
    print(f"trained {steps_run} steps ({settings.timesteps} asked; PPO runs whole rollouts of {settings.n_steps} x "
          f"{settings.n_envs} steps) in {wall - evaluation_s[0]:.1f} s of training, plus {evaluation_s[0]:.1f} s in "
          f"{len(rows)} evaluations and {oracle_s:.1f} s planning the held-out oracle; training started "
          f"{startup['training started'][0]:.1f} s after launch; held-out regret {rows[-1]['heldout_regret']:.4f} "
          f"(refill {rows[-1]['heldout_refill_regret']:.4f}) t/ha; wrote {out}", file=sys.stderr)
    return config
