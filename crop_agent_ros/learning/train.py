"""``crop-sim train``: train a PPO irrigation policy (Stable-Baselines3) on generated seasons.

Training runs on the batched task environment (``crop_sim_ros.task.sb3_vec``) of a generated-weather
scenario (default ``benton-generated``; the real held-out seasons are refused). The network sees the fixed
features of :mod:`crop_agent_ros.policies.sb3` and acts through its action mapping (default ``margin``: the
safety margin above the day's estimated no-stress water level); the training reward is the task's reward
with potential-based shaping by the crop's yield so far (``--reward-shaping``; evaluation always uses the
true reward). Every ``--eval-freq`` steps the deterministic policy runs on (a) fresh generated validation
seasons (a generator seed the training pool does not use; ``best_validation_model.zip`` keeps the best) and
(b) the held-out real seasons, whose regret against the hindsight oracle is only reported, never used to
choose anything (so the oracle is planned after training, and the progress lines show the held-out return
minus the refill rule's; the learning curve has the regrets). Before training starts, train prints how long
after launch that was, and the wall and CPU time of each part of the start-up. The shaping reads each field's true biomass from the batched environment's state (the
SB3 adapter does not pass it in ``infos``). Writes to ``--out`` (default ``runs/<name>``): ``model.zip`` with ``model.json`` (the
policy's feature and action settings, read by the loader), ``learning_curve.csv`` and ``.png``, and
``config.json`` (seed, scenario, hyper-parameters, package versions, the steps that ran (whole rollouts:
at least ``--timesteps``), training, evaluation and start-up times). ``--ship`` also copies the
policy to ``crop_agent_ros/policies/ppo_benton.zip`` (+ ``.json``).
"""

from __future__ import annotations

import csv
import json
import os
import platform
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HELD_OUT = ("heldout", "benton-2000", "paterson-1992", "paterson-1993", "paterson-1994", "paterson-1995")


# The defaults of the options below that depend on the algorithm, used when an option is not given: the gradient
# learners' (PPO, RecurrentPPO, TD3: the paper task's recipe) and the evolution strategies' (the family tasks'
# headline recipe, README "Evolution strategies": its learning rate is an Adam step on the parameters themselves,
# crop_agent_ros.learning.evolution; a generation is ~340,000 field-days, so its budget is in 100 M steps) and
# group-relative PPO's (crop_agent_ros.learning.grpo: an iteration is 128 whole seasons, ~20,000 field-days).
ALGORITHM_DEFAULTS = {
    "gradient": {"timesteps": 3_000_000, "eval_freq": 250_000, "validation_seasons": 64, "net_arch": "32,32",
                 "learning_rate": 1e-4, "final_learning_rate": 1e-5},
    "es": {"timesteps": 170_000_000, "eval_freq": 10_000_000, "validation_seasons": 32, "net_arch": "64,64",
           "learning_rate": 0.02, "final_learning_rate": 0.002},
    "grpo": {"timesteps": 12_000_000, "eval_freq": 1_000_000, "validation_seasons": 32, "net_arch": "64,64",
             "learning_rate": 3e-4, "final_learning_rate": 3e-5},
}


def fill_algorithm_defaults(args) -> None:
    """Each option of :data:`ALGORITHM_DEFAULTS` not given: the default of the run's algorithm."""
    algorithm = getattr(args, "algorithm", "ppo")
    defaults = ALGORITHM_DEFAULTS[algorithm if algorithm in ("es", "grpo") else "gradient"]
    for name, value in defaults.items():
        if getattr(args, name) is None:
            setattr(args, name, value)


def _default_help(name: str) -> str:
    values = {kind: ALGORITHM_DEFAULTS[kind][name] for kind in ("gradient", "es", "grpo")}
    shown = {kind: f"{v:,}" if isinstance(v, int) else f"{v}" for kind, v in values.items()}
    return f"default {shown['gradient']}; --algorithm es: {shown['es']}; grpo: {shown['grpo']}"


def add_arguments(parser) -> None:
    parser.add_argument("--name", default="ppo", help="run name (output in runs/<name> unless --out)")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default runs/<name>)")
    parser.add_argument("--scenario", default="benton-generated", help="training scenario (generated weather)")
    parser.add_argument("--eval-scenario", default="heldout", help="held-out seasons for the learning curve")
    parser.add_argument("--timesteps", type=int, default=None,
                        help=f"environment steps (field-days; {_default_help('timesteps')})")
    parser.add_argument("--n-envs", type=int, default=64, help="fields stepped together")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--eval-freq", type=int, default=None,
                        help=f"steps between evaluations ({_default_help('eval_freq')})")
    parser.add_argument("--eval-seeds", type=int, default=4, help="noise seeds per evaluation")
    parser.add_argument("--validation-seasons", type=int, default=None,
                        help=f"fresh generated validation seasons ({_default_help('validation_seasons')})")
    parser.add_argument("--action-mode", default="margin", choices=("mm", "target", "margin", "demand"))
    parser.add_argument("--feature-set", default="full", choices=("full", "compact", "phenology"))
    parser.add_argument("--margin-center", type=float, default=4.0, help="margin mode: mm above ET0/0.096 at a=0")
    parser.add_argument("--margin-span", type=float, default=15.0, help="margin mode: mm per unit of action")
    parser.add_argument("--demand-span", type=float, default=1.0,
                        help="demand mode: the level is (1 + span * a) * ET0/0.096 + margin-center")
    parser.add_argument("--learning-rate", type=float, default=None,
                        help=f"first learning rate ({_default_help('learning_rate')}, Adam's step on the parameters)")
    parser.add_argument("--final-learning-rate", type=float, default=None,
                        help=f"linear decay to this value ({_default_help('final_learning_rate')})")
    parser.add_argument("--n-steps", type=int, default=256, help="rollout length per field")
    parser.add_argument("--batch-size", type=int, default=2048)
    parser.add_argument("--n-epochs", type=int, default=10)
    parser.add_argument("--gamma", type=float, default=1.0,
                        help="1: the season is finite and the yield comes at its end")
    parser.add_argument("--gae-lambda", type=float, default=0.95)
    parser.add_argument("--clip-range", type=float, default=0.2)
    parser.add_argument("--ent-coef", type=float, default=0.0)
    parser.add_argument("--net-arch", default=None, help=f"hidden layer sizes ({_default_help('net_arch')})")
    parser.add_argument("--log-std-init", type=float, default=-2.5)
    parser.add_argument("--reward-shaping", default="biomass", choices=("none", "biomass"),
                        help="potential-based shaping of the training reward (evaluation: true reward)")
    parser.add_argument("--ship", action="store_true", help="copy the policy to crop_agent_ros/policies/ppo_benton")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    from .train_task import add_task_arguments
    add_task_arguments(parser)


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


def silent_logger():
    """An SB3 logger that writes nowhere: with ``verbose=0`` SB3's own default still makes an empty
    ``/tmp/SB3-<time>`` folder on every ``learn`` (245 of them after one session's tests and sweeps)."""
    from stable_baselines3.common.logger import Logger
    return Logger(folder=None, output_formats=[])


def validation_scenario(scenario, n_seasons: int, seed: int):
    """Fresh generated seasons: the training scenario's generator with a seed its pool does not use
    (seed + 10,007 + the training seed). A mixture validates on its first part's generator, re-seeded alike."""
    if scenario.weather.kind == "mixture":
        from crop_sim_ros.task.scenario import get_scenario
        first = get_scenario(scenario.weather.mixture[0], scenario.data_dir)
        scenario = replace(scenario, sowing_date=first.sowing_date, max_season_days=first.max_season_days,
                           weather=first.weather)
    return replace(scenario, name=f"{scenario.name}-validation",
                   weather=replace(scenario.weather, seed=scenario.weather.seed + 10_007 + seed, n_seasons=n_seasons))


def seconds_since_launch() -> float:
    """Seconds since this process started (its start time in /proc, 10 ms resolution): the interpreter's
    start-up and imports count too."""
    after_name = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
    start_s = int(after_name[19]) / os.sysconf("SC_CLK_TCK")  # field 22, starttime, in clock ticks since boot
    return float(Path("/proc/uptime").read_text().split()[0]) - start_s


def package_versions() -> dict:
    import gymnasium
    import stable_baselines3
    import torch
    return {"python": platform.python_version(), "numpy": np.__version__, "gymnasium": gymnasium.__version__,
            "stable_baselines3": stable_baselines3.__version__, "torch": torch.__version__,
            "platform": platform.platform()}


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
    fig.savefig(path, dpi=110)
    plt.close(fig)


def train(args) -> dict:
    """The paper task's training; ``args`` as :func:`run` completes them (the algorithm's defaults filled)."""
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

    scenario = scenario_of(args.scenario)
    if scenario.name in HELD_OUT or scenario.weather.kind != "generator":
        raise SystemExit(f"crop-sim train: refusing to train on {scenario.name!r}: training uses generated "
                         f"seasons only (held-out: {', '.join(HELD_OUT)})")
    out = Path(args.out) if args.out else Path("runs") / args.name
    out.mkdir(parents=True, exist_ok=True)
    net_arch = [int(x) for x in str(args.net_arch).split(",") if x.strip()]
    hyper = {k: getattr(args, k) for k in ("timesteps", "n_envs", "action_mode", "learning_rate",
                                           "final_learning_rate", "n_steps", "batch_size", "n_epochs", "gamma",
                                           "gae_lambda", "clip_range", "ent_coef", "log_std_init", "reward_shaping",
                                           "feature_set", "margin_center", "margin_span", "demand_span")}
    hyper["net_arch"] = net_arch

    # evaluation sets: held-out real seasons (reported only) and fresh generated validation seasons
    heldout = scenario_of(args.eval_scenario)
    heldout_contexts = season_contexts(heldout)
    validation = validation_scenario(scenario, args.validation_seasons, args.seed)
    eval_seeds = list(range(1000, 1000 + args.eval_seeds))
    refill = tuned_refill_policy()

    def score(policy, scen, contexts=None):
        seasons = np.arange(len(contexts) if contexts else args.validation_seasons)
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
    mapping = {"margin_center_mm": args.margin_center, "margin_span_mm": args.margin_span}
    if args.action_mode == "demand":
        mapping["demand_span"] = args.demand_span
    venv = feature_action_wrapper(training_vec_env(scenario, args.n_envs, args.seed), args.action_mode,
                                  args.feature_set, mapping, args.reward_shaping, args.gamma, float(params.harvest_index[0]),
                                  float(params.initial_biomass_kg_ha[0]) / 1000.0)
    lr0, lr1 = args.learning_rate, args.final_learning_rate
    model = PPO("MlpPolicy", venv, learning_rate=lambda progress: lr1 + (lr0 - lr1) * progress,
                n_steps=args.n_steps, batch_size=args.batch_size, n_epochs=args.n_epochs, gamma=args.gamma,
                gae_lambda=args.gae_lambda, clip_range=args.clip_range, ent_coef=args.ent_coef,
                policy_kwargs={"net_arch": net_arch, "log_std_init": args.log_std_init}, seed=args.seed,
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
                self.next_eval += args.eval_freq
                self.evaluate()
            return True

        def _on_training_end(self) -> None:
            if not rows or rows[-1]["timesteps"] != self.num_timesteps:
                self.evaluate()

        def evaluate(self):
            evaluation_started = time.perf_counter()
            policy = PolicyOfModel(self.model, args.action_mode, args.feature_set, mapping)
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
                self.model.save(out / "best_validation_model.zip")
            print(f"[{row['timesteps']:>9}] {row['wall_s']:>7.1f} s  validation - refill "
                  f"{row['validation_minus_refill']:+.4f}  held-out - refill {ret.mean() - r_ref.mean():+.4f} t/ha",
                  file=sys.stderr, flush=True)
            evaluation_s[0] += time.perf_counter() - evaluation_started

    callback = Curve()
    model.learn(total_timesteps=args.timesteps, callback=callback, progress_bar=not args.no_progress)
    wall = time.perf_counter() - started
    steps_run = int(model.num_timesteps)  # whole rollouts of n_steps x n_envs: at least --timesteps
    model.save(out / "model.zip")
    oracle_started = time.perf_counter()
    oracle = OraclePolicy()
    oracle.begin_season(heldout_contexts)
    heldout_oracle = np.array([r.return_value for r in oracle.results])
    oracle_s = time.perf_counter() - oracle_started
    for row, ret in zip(rows, heldout_returns):
        row.update(heldout_regret=float((heldout_oracle - ret).mean()),
                   heldout_refill_regret=float((heldout_oracle - r_ref).mean()))
    policy_config = {"action_mode": args.action_mode, "feature_set": args.feature_set, "action_mapping": mapping,
                     "feature_version": FEATURE_VERSION, "n_features": FEATURE_SETS[args.feature_set],
                     "trained_on": scenario.name, "seed": args.seed, "timesteps": args.timesteps,
                     "note": "deterministic actions; features and action mapping: crop_agent_ros.policies.sb3"}
    (out / "model.json").write_text(json.dumps(policy_config, indent=2) + "\n")
    if (out / "best_validation_model.zip").exists():
        (out / "best_validation_model.json").write_text(json.dumps(
            {**policy_config, "timesteps_at_save": best["timesteps"]}, indent=2) + "\n")
    with open(out / "learning_curve.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    plot_curve(rows, out / "learning_curve.png", f"PPO on {scenario.name}, seed {args.seed}")
    command = ("crop-sim train " + " ".join(sys.argv[2:])) if len(sys.argv) > 1 and sys.argv[1] == "train" else None
    config = {"name": args.name, "command": command,
              "arguments": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()
                            if not k.startswith("_")},
              "seed": args.seed, "scenario": scenario.name, "training_weather": {
                  "kind": scenario.weather.kind, "generator": scenario.weather.generator,
                  "seed": scenario.weather.seed, "n_seasons": scenario.weather.n_seasons},
              "validation_weather": {"generator_seed": validation.weather.seed, "n_seasons": args.validation_seasons},
              "eval_scenario": heldout.name, "eval_noise_seeds": eval_seeds, "hyper_parameters": hyper,
              "reward": ("evaluation: the task's true reward (C_I * mm daily + yield t/ha at harvest); training: "
                         + ("the true reward" if args.reward_shaping == "none" else
                            "plus potential-based shaping gamma*Phi(s') - Phi(s), Phi = HI * true biomass t/ha")),
              "policy": policy_config, "timesteps_run": steps_run, "wall_time_s": round(wall, 1),
              "training_time_s": round(wall - evaluation_s[0], 1), "evaluation_time_s": round(evaluation_s[0], 1),
              "heldout_oracle_time_s": round(oracle_s, 1),
              "evaluations": len(rows),
              "startup_wall_cpu_s": {name: [round(wall, 2), round(cpu, 2)] for name, (wall, cpu) in startup.items()},
              "torch_threads": torch.get_num_threads(),
              "best_validation": best, "final": rows[-1], "versions": package_versions()}
    (out / "config.json").write_text(json.dumps(config, indent=2, default=str) + "\n")
    if args.ship:
        from ..policies.sb3 import SHIPPED_PPO
        shutil.copyfile(out / "model.zip", SHIPPED_PPO)
        (SHIPPED_PPO.with_suffix(".json")).write_text(json.dumps({**policy_config, "training": config}, indent=2,
                                                                 default=str) + "\n")
    print(f"trained {steps_run} steps ({args.timesteps} asked; PPO runs whole rollouts of {args.n_steps} x "
          f"{args.n_envs} steps) in {wall - evaluation_s[0]:.1f} s of training, plus {evaluation_s[0]:.1f} s in "
          f"{len(rows)} evaluations and {oracle_s:.1f} s planning the held-out oracle; training started "
          f"{startup['training started'][0]:.1f} s after launch; held-out regret {rows[-1]['heldout_regret']:.4f} "
          f"(refill {rows[-1]['heldout_refill_regret']:.4f}) t/ha; wrote {out}", file=sys.stderr)
    return config


# Upper bounds of what a user may ask of training (refused above them with one line, exit 2).
MAX_TIMESTEPS = 1_000_000_000
MAX_TRAINING_FIELDS = 100_000


def run(args) -> int:
    from crop_sim_ros.usage import UsageError
    from .evolution import es_options_given
    from .grpo import grpo_options_given
    fill_algorithm_defaults(args)
    for name, value, high in (("--timesteps", args.timesteps, MAX_TIMESTEPS), ("--n-envs", args.n_envs, MAX_TRAINING_FIELDS),
                              ("--n-steps", args.n_steps, 100_000), ("--batch-size", args.batch_size, 10_000_000),
                              ("--eval-freq", args.eval_freq, MAX_TIMESTEPS),
                              ("--validation-seasons", args.validation_seasons, 10_000),
                              ("--history", getattr(args, "history", 1), 365)):
        if not 1 <= value <= high:
            raise UsageError(f"{name} {value}: must be in 1..{high:,}")
    if args.task is not None:
        from .train_task import train_task
        train_task(args)
        return 0
    # the family agent's options: refused on the paper's task rather than ignored
    family_only = [flag for flag, given in (
        ("--imitate", getattr(args, "imitate", None)), ("--paw-filter", getattr(args, "paw_filter", False)),
        ("--outlook", getattr(args, "outlook", False)),
        ("--training-seasons", getattr(args, "training_seasons", None) is not None),
        ("--sde", getattr(args, "sde", None) is not None),
        ("--critic-warmup", getattr(args, "critic_warmup", 0) != 0),
        ("--critic-hindsight", getattr(args, "critic_hindsight", False)),
        ("--log-std-final", getattr(args, "log_std_final", None) is not None),
        ("--action residual", getattr(args, "action", "mm") != "mm"), ("--history", getattr(args, "history", 1) != 1),
        ("--action-noise", getattr(args, "action_noise", None) is not None),
        ("--gradient-steps", getattr(args, "gradient_steps", None) is not None),
        *((flag, True) for flag in es_options_given(args)), *((flag, True) for flag in grpo_options_given(args)),
        (f"--algorithm {getattr(args, 'algorithm', 'ppo')}", getattr(args, "algorithm", "ppo") != "ppo")) if given]
    if family_only:
        raise UsageError(f"{', '.join(family_only)}: with --task only (a family task's agent)")
    train(args)
    return 0
