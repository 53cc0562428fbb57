"""``crop-sim train --task TASK``: train a family agent (PPO, RecurrentPPO, TD3, evolution strategies:
:mod:`.evolution`, or PPO with group-relative advantages: :mod:`.grpo`) on a family task's training seasons
(generated weather only; the held-out real seasons and the held-out climate are never seen).

The network's observation and action are those of :mod:`crop_agent_ros.learning.agent` (normalised raw
observation, action in mm; ``--action residual``: a correction of the task's tuned rule, ``family_<task>.json``,
whose parameters are saved with the policy, with a zero-initialised last layer so that training starts at the
rule). Training reward of the gradient learners: the task's reward (USD/ha) divided by ``REWARD_SCALE_USD`` and
shaped by a potential (Ng et al. 1999), Phi(s) = the value of the yield the crop would give if harvested
now (tuber price / dry-matter fraction x harvest index x true biomass), 0 at the season's end: the yield paid
at harvest is spread over the days that grew it; the optimal policy is unchanged, and every evaluation
uses the true reward.

Along the way (every ``--eval-freq`` steps) the deterministic policy runs on fixed validation seasons (a
generator seed the training pool does not use) with fixed terms and is saved as ``checkpoint_<steps>.zip``
(the evaluation's learning curves on held-out seasons read them); the curve (CSV), a checkpoint at 1 % of
the budget (``early_model.zip``, for the "learning is real" check), the final policy (``final_model.zip``) and
the run's policy (``model.zip`` + ``model.json``: the checkpoint with the best validation return, as
:func:`select_model` picks it) go to ``--out``. Nothing held out is used to choose anything.
"""

from __future__ import annotations

import contextlib
import copy
import csv
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from .train import silent_logger, validation_scenario
from .agent import ACTION_KINDS, ACTION_SCALE_MM, ALGORITHMS, RESIDUAL_SPAN_MM, AgentInterface, ObservationScaler
from .evolution import add_es_arguments, es_options_given, es_settings
from .grpo import add_grpo_arguments, grpo_options_given, grpo_settings

REWARD_SCALE_USD = 1000.0
TRAINING_KINDS = ("generator", "mixture")
# The columns that count days: their meaning for the crop differs between climates (a potato crop matures in
# ~107 days in Maricopa sown February 28, 137-173 days in climates4-quota's parts), where thermal time's does not.
# (Hiding them from ES on climates6-quota made its transfer to that climate worse: README, "sown late".)
CLIMATE_BOUND_DAY_COLUMNS = ("days_since_sowing", "season_days_left")
TD3_BUFFER_FIELD_DAYS = 1_000_000  # about 6,700 seasons: every transition of the first sixth of a 6 M-step run
TD3_DEFAULTS = {"action_noise": 0.2, "gradient_steps": 16}


def add_task_arguments(parser) -> None:
    parser.add_argument("--task", default=None, help="a family task (e.g. benton-quota): trains a family agent")
    parser.add_argument("--algorithm", default="ppo", choices=ALGORITHMS)
    parser.add_argument("--history", type=int, default=1, help="observations the network sees (frame stack)")
    parser.add_argument("--action", default="mm", choices=ACTION_KINDS,
                        help="with --task: mm (the headline agent: a in [-1, 1] -> 0..25 mm) or residual (a variant: "
                             f"the tuned rule's mm + a x {RESIDUAL_SPAN_MM:g} mm, clipped to 0..25 mm)")
    parser.add_argument("--paw-filter", action="store_true",
                        help="with --task: the network also sees a PAW estimate, the checkbook corrected by each "
                             "reading (a Kalman filter knowing the task's sensor error; a labelled feature)")
    parser.add_argument("--outlook", action="store_true",
                        help="with --task: the network also sees a climate outlook, the quota left against the "
                             "demand the field's climate normally brings in the next 60 days and that demand's "
                             "trend (crop_agent_ros.policies.outlook; a labelled feature)")
    parser.add_argument("--hide", default=None, metavar="COLUMNS",
                        help="with --task: observation columns the network cannot read (comma-separated names of "
                             "crop_sim_ros.task.layout.EXTENDED; each scales to 0), e.g. "
                             f"{','.join(CLIMATE_BOUND_DAY_COLUMNS)} (the network must then time its water by "
                             "thermal time; a labelled feature)")
    parser.add_argument("--sde", type=int, default=None, metavar="DAYS",
                        help="with --task: generalized state-dependent exploration (gSDE, Raffin et al. 2021) "
                             "instead of independent daily noise: the exploration is a function of the observation "
                             "whose weights are redrawn every DAYS days of each field (0: once per rollout)")
    parser.add_argument("--critic-hindsight", action="store_true",
                        help="with --task, PPO: the value network also sees what the field's season still holds (its "
                             "potential yield, the next days' rain, ET0 and radiation: crop_sim_ros.task.hindsight), "
                             "so that the weather's luck is in the baseline, not in the advantage; the policy never "
                             "sees it and the policy files hold the policy alone (an asymmetric critic)")
    parser.add_argument("--critic-warmup", type=int, default=0, metavar="STEPS",
                        help="with --task: for the first STEPS steps only the value network learns (the policy "
                             "acts, unchanged): a critic fitted to a cloned policy before PPO moves it")
    parser.add_argument("--log-std-final", type=float, default=None, metavar="LOG_STD",
                        help="with --task: the exploration's log std is not learned but moves linearly from "
                             "--log-std-init to LOG_STD over the training, so that what PPO improves (the return "
                             "of the noisy policy) approaches what is evaluated (its mean action)")
    parser.add_argument("--action-noise", type=float, default=None, metavar="SIGMA",
                        help="with --algorithm td3: the exploration's Gaussian noise on the action in [-1, 1] "
                             f"(default {TD3_DEFAULTS['action_noise']:g} = "
                             f"{TD3_DEFAULTS['action_noise'] * ACTION_SCALE_MM / 2:g} mm)")
    parser.add_argument("--gradient-steps", type=int, default=None, metavar="N",
                        help="with --algorithm td3: gradient steps after each step of the fields (--n-envs "
                             f"field-days; default {TD3_DEFAULTS['gradient_steps']})")
    add_es_arguments(parser)
    add_grpo_arguments(parser)
    parser.add_argument("--training-seasons", type=int, default=None, metavar="N",
                        help="with --task on a generated task: train on a pool of N seasons drawn by the task's "
                             "generator (default: the task's own pool of 1,000)")
    parser.add_argument("--imitate", nargs="+", default=None, metavar="GLOB",
                        help="with --task: first fit the policy to these demonstrations of the causal MPC "
                             "(`crop-sim demonstrate`; behaviour cloning), then PPO (or --algorithm es) on the "
                             "reward (a variant)")
    parser.add_argument("--imitation-epochs", type=int, default=100, help="epochs of behaviour cloning")
    parser.add_argument("--imitation-keep-best", action="store_true",
                        help="end the cloning with the epoch of least held-out error, not the last (early stopping)")


@contextlib.contextmanager
def frozen_actor(policy):
    """Inside: the policy network, its action layer and its exploration scale take no gradient (the value network
    still learns: PPO's step leaves parameters without a gradient as they are)."""
    actor = [*policy.mlp_extractor.policy_net.parameters(), *policy.action_net.parameters(), policy.log_std]
    if getattr(policy, "lstm_actor", None) is not None:  # RecurrentPPO's actor memory
        actor += list(policy.lstm_actor.parameters())
    learning = [parameter.requires_grad for parameter in actor]
    for parameter in actor:
        parameter.requires_grad_(False)
    try:
        yield
    finally:
        for parameter, was in zip(actor, learning):
            parameter.requires_grad_(was)


def set_exploration(model, log_std: float) -> None:
    """The policy's exploration log std (every action dimension, every gSDE weight) is ``log_std`` from now on; a
    gSDE policy draws its noise weights again with it."""
    import torch
    with torch.no_grad():
        model.policy.log_std.fill_(log_std)
    if model.use_sde:
        model.policy.reset_noise(model.n_envs)


def hyper_parameters(args) -> dict:
    """The run's learning settings, those its algorithm uses."""
    shared = {k: getattr(args, k) for k in ("learning_rate", "final_learning_rate", "batch_size", "gamma")}
    if args.algorithm == "td3":
        noise, steps = td3_settings(args)
        return {**shared, "action_noise": noise, "gradient_steps": steps, "buffer_field_days": TD3_BUFFER_FIELD_DAYS}
    if args.algorithm == "es":
        return {"learning_rate": args.learning_rate, "final_learning_rate": args.final_learning_rate,
                **{f"es_{k}": v for k, v in es_settings(args).items()}}
    if args.algorithm == "grpo":
        return {**{k: getattr(args, k) for k in ("learning_rate", "final_learning_rate", "batch_size", "n_epochs",
                                                  "clip_range", "log_std_init")},
                **{f"grpo_{k}": v for k, v in grpo_settings(args).items()}, "exploration": "gSDE, one draw per season"}
    return {**shared, **{k: getattr(args, k) for k in ("n_steps", "n_epochs", "gae_lambda", "clip_range", "ent_coef",
                                                       "log_std_init")},
            "critic_hindsight": bool(args.critic_hindsight), **exploration(args.sde)}


def td3_settings(args) -> tuple[float, int]:
    """(action noise, gradient steps) of a TD3 run: the options given, else TD3_DEFAULTS."""
    noise = TD3_DEFAULTS["action_noise"] if args.action_noise is None else args.action_noise
    steps = TD3_DEFAULTS["gradient_steps"] if args.gradient_steps is None else args.gradient_steps
    return noise, steps


def td3_model(venv, args, net_arch, learning_rate):
    """Stable-Baselines3 TD3 on the fields of ``venv``: replay of the last TD3_BUFFER_FIELD_DAYS field-days,
    ``--gradient-steps`` updates of minibatches of ``--batch-size`` after each step of the fields, learning from
    the first 1 % of ``--timesteps`` (at most 20,000 field-days) on; Gaussian action noise ``--action-noise``.
    (Options checked by :func:`check_options`.)"""
    from stable_baselines3 import TD3
    from stable_baselines3.common.noise import NormalActionNoise
    noise, steps = td3_settings(args)
    return TD3("MlpPolicy", venv, learning_rate=learning_rate, buffer_size=TD3_BUFFER_FIELD_DAYS,
               learning_starts=min(20_000, args.timesteps // 100), batch_size=args.batch_size, gamma=args.gamma,
               train_freq=1, gradient_steps=steps, action_noise=NormalActionNoise(np.zeros(1), np.full(1, noise)),
               policy_kwargs={"net_arch": net_arch}, seed=args.seed, device="cpu", verbose=0)


def check_options(args) -> None:
    """UsageError, before any work, for an option the run's algorithm does not have or a value out of range."""
    from crop_sim_ros.usage import UsageError
    ppo_only = [flag for flag, value in (
        ("--sde", args.sde is not None), ("--critic-warmup", args.critic_warmup),
        ("--log-std-final", args.log_std_final is not None)) if value]
    if args.algorithm in ("td3", "es", "grpo") and ppo_only:
        raise UsageError(f"{', '.join(ppo_only)}: for PPO only, not --algorithm {args.algorithm}")
    # (evolution strategies' candidates act through the same interface, so they correct the rule as PPO does)
    if args.algorithm in ("td3", "grpo") and args.action == "residual":
        raise UsageError(f"--action residual: for PPO and --algorithm es only, not --algorithm {args.algorithm}")
    if args.critic_hindsight and args.algorithm != "ppo":  # (not recurrent-ppo either: its critic is an LSTM's)
        raise UsageError(f"--critic-hindsight: for PPO only, not --algorithm {args.algorithm}")
    if args.critic_hindsight and args.imitate:
        raise UsageError("--critic-hindsight: for PPO from a fresh network, not with --imitate")
    if args.algorithm in ("td3", "grpo") and args.imitate:  # (es starts from the cloned network, as PPO does)
        raise UsageError(f"--imitate: for PPO and --algorithm es only, not --algorithm {args.algorithm}")
    td3_only = [flag for flag, value in (("--action-noise", args.action_noise),
                                         ("--gradient-steps", args.gradient_steps)) if value is not None]
    for algorithm, flags in (("td3", td3_only), ("es", es_options_given(args)), ("grpo", grpo_options_given(args))):
        if args.algorithm != algorithm and flags:
            raise UsageError(f"{', '.join(flags)}: for --algorithm {algorithm} only")
    if args.algorithm == "td3":
        noise, steps = td3_settings(args)
        if not noise >= 0 or not 1 <= steps <= 10_000:
            raise UsageError(f"--action-noise {noise} (>= 0) / --gradient-steps {steps} (1..10,000): out of range")
    if args.algorithm == "es":
        es = es_settings(args)
        if not (1 <= es["pairs"] <= 1_000 and 0 < es["noise_std"] <= 10 and 1 <= es["seasons"] <= 1_000):
            raise UsageError(f"--es-pairs {es['pairs']} (1..1,000) / --es-noise-std {es['noise_std']} (0..10] / "
                             f"--es-seasons {es['seasons']} (1..1,000): out of range")
    if args.algorithm == "grpo":
        grpo = grpo_settings(args)
        if not (1 <= grpo["groups"] <= 1_000 and 2 <= grpo["group_size"] <= 1_000):
            raise UsageError(f"--grpo-groups {grpo['groups']} (1..1,000) / --grpo-group-size {grpo['group_size']} "
                             "(2..1,000): out of range")
    if not 0 <= args.critic_warmup < args.timesteps:
        raise UsageError(f"--critic-warmup {args.critic_warmup}: steps in 0..--timesteps ({args.timesteps}) - 1")
    exploration(args.sde)  # a negative count is refused
    hidden_columns(getattr(args, "hide", None))  # an unknown column is refused


def hidden_columns(text: str | None) -> tuple[str, ...]:
    """``--hide``'s column names, in layout order (UsageError naming the columns that exist for an unknown one)."""
    if not text:
        return ()
    from crop_sim_ros.task.layout import EXTENDED
    from crop_sim_ros.usage import UsageError
    names = {name.strip() for name in text.split(",") if name.strip()}
    unknown = sorted(names - set(EXTENDED.names))
    if unknown:
        raise UsageError(f"--hide {', '.join(unknown)}: no such observation column; columns: {', '.join(EXTENDED.names)}")
    return tuple(name for name in EXTENDED.names if name in names)


def exploration(sde_days: int | None) -> dict:
    """SB3's exploration arguments: independent Gaussian noise each day (None), or gSDE with its noise weights
    redrawn every ``sde_days`` steps (0: at each rollout's start; SB3's -1). UsageError for a negative count."""
    if sde_days is None:
        return {}
    if sde_days < 0:
        from crop_sim_ros.usage import UsageError
        raise UsageError(f"--sde {sde_days}: days between noise draws, 0 (once per rollout) or more")
    return {"use_sde": True, "sde_sample_freq": sde_days if sde_days > 0 else -1}


def training_pool(scenario, n_seasons: int | None):
    """``scenario`` with a pool of ``n_seasons`` seasons drawn by its generator with its seed (the pool is drawn at
    once, so it is another draw than the scenario's own pool); None: as it is. UsageError for a mixture or an
    out-of-range count. Validation and evaluation seasons use other seeds either way."""
    if n_seasons is None:
        return scenario
    from crop_sim_ros.task.scenario import MAX_GENERATED_SEASONS
    from crop_sim_ros.usage import UsageError
    if scenario.weather.kind != "generator":
        raise UsageError(f"--training-seasons: {scenario.name!r} mixes other scenarios' pools; give it for a "
                         "task on one generator")
    if not 1 <= n_seasons <= MAX_GENERATED_SEASONS:
        raise UsageError(f"--training-seasons {n_seasons}: must be in 1..{MAX_GENERATED_SEASONS:,}")
    return replace(scenario, weather=replace(scenario.weather, n_seasons=n_seasons))


def fit_scaler(scenario, seed: int, seasons: int = 64, demonstrations: np.ndarray | None = None) -> ObservationScaler:
    """Observation statistics over ``seasons`` training seasons under the default water-budget rule (a column
    they hold constant, over them and the ``demonstrations``' observations: :meth:`ObservationScaler.fit`)."""
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
    return ObservationScaler.fit(np.concatenate(seen), demonstrations)


def training_env(scenario, n_envs: int, seed: int, interface: AgentInterface, harvest_index: float,
                 dry_matter_fraction: float, hindsight=None):
    """The SB3 VecEnv the network trains on (``interface``'s input in, [-1, 1] action out, scaled shaped
    reward). With ``hindsight`` (a :class:`~.asymmetric.HindsightScaler`), each field's scaled hindsight values
    of its season and day follow the interface's input (for an asymmetric critic; the actor does not read
    them)."""
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecEnvWrapper
    from crop_sim_ros.task.layout import EXTENDED
    from crop_sim_ros.task.sb3_vec import IrrigationSB3VecEnv

    price = EXTENDED.index("tuber_price_usd_per_t")
    pool = None
    if interface.outlook is not None:
        from ..policies.outlook import pool_climates
        pool = pool_climates(scenario)

    class TaskWrapper(VecEnvWrapper):
        def __init__(self):
            venv = IrrigationSB3VecEnv(n_envs, scenario, seed=seed)
            extra = 0 if hindsight is None else len(hindsight.mean)
            super().__init__(venv, observation_space=spaces.Box(-10.0, 10.0, (interface.input_size + extra,),
                                                                np.float32),
                             action_space=spaces.Box(-1.0, 1.0, (1,), np.float32))
            self.fields = venv.venv

        def _with_hindsight(self, inputs, season=None, day=None):
            """``inputs`` with the fields' hindsight values appended (of ``season``, ``day``; default: every
            field's now); ``inputs`` as they are without a hindsight critic."""
            if hindsight is None:
                return inputs
            if season is None:
                season, day = self.fields.field_seasons, self.fields.field_days
            return np.concatenate([inputs, hindsight(season, day)], axis=-1)

        def _value_per_t(self, raw):
            return raw[:, price] / dry_matter_fraction

        def _tell_outlook(self):
            """The fields' climates for the seasons they are in now (an agent with a climate outlook)."""
            if interface.outlook is not None:
                fields = [pool[k] for k in self.venv.venv.field_seasons]
                interface.outlook.set_fields([c for c, _ in fields], [d for _, d in fields])

        def reset(self):
            raw = self.venv.reset()
            interface.reset()
            self._tell_outlook()
            self.phi = np.zeros(self.num_envs)
            return self._with_hindsight(interface.observe(raw)[0])

        def step_async(self, actions):
            if hindsight is not None:  # (a season ends on the day after the one each field steps from)
                self.before = self.fields.field_seasons, self.fields.field_days
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
            ended = None
            if terminal and interface.outlook is not None:
                ended = copy.deepcopy(interface.outlook)  # the ended seasons' climates, for their last inputs
            self._tell_outlook()
            inputs, terminal_inputs = interface.observe(raw, terminal, ended)
            inputs = self._with_hindsight(inputs)
            for i, terminal_input in terminal_inputs.items():
                if hindsight is not None:
                    season, day = self.before
                    terminal_input = self._with_hindsight(terminal_input[None], season[i:i + 1], day[i:i + 1] + 1)[0]
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
    shutil.copyfile(source, out / "model.zip")
    config = json.loads(source.with_suffix(".json").read_text())
    config["selected_by"] = "best validation return of the run's checkpoints (generated seasons, unused seed)"
    (out / "model.json").write_text(json.dumps(config, indent=1) + "\n")
    return {"timesteps": steps, "validation_return": float(best["validation_return"]), "file": source.name}


def train_task(args) -> dict:
    import torch
    from crop_sim_ros.task import core
    from crop_sim_ros.task.scenario import get_scenario
    from ..policies.family import FarmFacts, SoilWaterFilter, WaterBudgetRule
    from ..policies.family_tuning import draw_terms, rule_file, rule_record, tuned_rule
    from ..policies.rollout import run_episodes
    from .agent import LearnedPolicy
    from .train import fill_algorithm_defaults

    torch.set_num_threads(1)
    launched = time.perf_counter()
    fill_algorithm_defaults(args)
    scenario = get_scenario(args.task)
    if not scenario.is_family_task:
        raise SystemExit(f"crop-sim train: {args.task!r} is not a family task (its observation has 20 values); "
                         "train the paper's task without --task")
    if scenario.weather.kind not in TRAINING_KINDS:
        raise SystemExit(f"crop-sim train: refusing to train on {scenario.name!r}: training uses generated seasons "
                         "only (real seasons and the held-out climate are for evaluation)")
    check_options(args)
    scenario = training_pool(scenario, args.training_seasons)
    # the distinct training seasons an ES generation / a GRPO iteration draws from the pool
    drawn = {"es": ("--es-seasons", es_settings, "seasons"), "grpo": ("--grpo-groups", grpo_settings, "groups")}
    if args.algorithm in drawn:
        flag, settings, key = drawn[args.algorithm]
        if (count := settings(args)[key]) > scenario.n_seasons:
            from crop_sim_ros.usage import UsageError
            raise UsageError(f"{flag} {count}: the training pool has {scenario.n_seasons} seasons")
    out = Path(args.out) if args.out else Path("runs") / f"{args.task}-{args.algorithm}-s{args.seed}"
    out.mkdir(parents=True, exist_ok=True)
    params = core.task_params(scenario)
    demonstrations = None
    if getattr(args, "imitate", None):
        from .imitation import load_demonstrations
        if not 1 <= args.imitation_epochs <= 100_000:
            from crop_sim_ros.usage import UsageError
            raise UsageError(f"--imitation-epochs {args.imitation_epochs}: must be in 1..100,000")
        demonstrations = load_demonstrations(args.imitate, scenario.name)
    scaler = replace(fit_scaler(scenario, args.seed,
                                demonstrations=None if demonstrations is None else demonstrations["observations"]),
                     hidden=hidden_columns(getattr(args, "hide", None)))
    net_arch = [int(x) for x in str(args.net_arch).split(",") if x.strip()]
    action_kind = getattr(args, "action", "mm")
    rule = None
    if action_kind == "residual":
        try:
            rule = tuned_rule(scenario.name)
        except FileNotFoundError as error:
            from crop_sim_ros.usage import UsageError
            raise UsageError(f"--action residual corrects the task's tuned rule: {error}") from None
    paw_filter = None
    if getattr(args, "paw_filter", False):
        # the sensor's stated error is the task's PAW noise (a farmer knows the probe's specification)
        paw_filter = SoilWaterFilter(FarmFacts.of_scenario(scenario).capacity_mm, scenario.noise.paw_mm)
    outlook = None
    if getattr(args, "outlook", False):
        from ..policies.outlook import ClimateOutlook
        outlook = ClimateOutlook()
    interface = AgentInterface(scaler, args.history, action_kind, rule, paw_filter, outlook)
    hindsight = None
    if args.critic_hindsight:
        from crop_sim_ros.task.core import scenario_table
        from crop_sim_ros.task.hindsight import SeasonHindsight
        from .asymmetric import HindsightScaler
        table = scenario_table(scenario)
        hindsight = HindsightScaler(SeasonHindsight(table), table.n_days)
    if args.algorithm in ("es", "grpo"):  # they run their own seasons: the network's spaces are all they need
        from .agent import network_spaces
        venv = network_spaces(interface.input_size)
    else:
        venv = training_env(scenario, args.n_envs, args.seed, interface, float(params.fields.harvest_index[0]),
                            params.dry_matter_fraction, hindsight)
    lr0, lr1 = args.learning_rate, args.final_learning_rate
    common = dict(learning_rate=lambda progress: lr1 + (lr0 - lr1) * progress, n_steps=args.n_steps,
                  batch_size=args.batch_size, n_epochs=args.n_epochs, gamma=args.gamma, gae_lambda=args.gae_lambda,
                  clip_range=args.clip_range, ent_coef=args.ent_coef, seed=args.seed, device="cpu", verbose=0,
                  **exploration(args.sde))
    if args.algorithm == "td3":
        model = td3_model(venv, args, net_arch, common["learning_rate"])
    elif args.algorithm in ("ppo", "es", "grpo"):  # (es, grpo: the PPO policy holds the actor; PPO never learns)
        from stable_baselines3 import PPO
        policy_kwargs = {"net_arch": net_arch, "log_std_init": args.log_std_init}
        if hindsight is None:
            model = PPO("MlpPolicy", venv, policy_kwargs=policy_kwargs, **common)
        else:
            from .asymmetric import HindsightCriticPolicy
            model = PPO(HindsightCriticPolicy, venv, policy_kwargs={**policy_kwargs,
                                                                    "actor_inputs": interface.input_size}, **common)
    else:
        from sb3_contrib import RecurrentPPO
        model = RecurrentPPO("MlpLstmPolicy", venv, policy_kwargs={"net_arch": net_arch, "log_std_init": args.log_std_init,
                                                                   "lstm_hidden_size": 64}, **common)
    model.set_logger(silent_logger())
    if action_kind == "residual":
        # Start at the rule: a zero last layer gives a = 0 (no correction) for every input, so the deterministic
        # policy at step 0 is the tuned rule; the layer's gradient is not zero, so it (and then the hidden
        # layers behind it) learn from the first update.
        with torch.no_grad():
            model.policy.action_net.weight.zero_()
            model.policy.action_net.bias.zero_()
    imitation = None
    if demonstrations is not None:
        from .imitation import clone
        # the run's "1 %" policy is the network after 1 % of its behaviour-cloning epochs (what "learning is
        # real" compares the final policy with): kept in memory until the policy files can be written
        early_epoch = max(1, args.imitation_epochs // 100)
        early_weights = {}

        def keep_early(epoch: int) -> None:
            if epoch == early_epoch:
                early_weights.update({k: v.clone() for k, v in model.policy.state_dict().items()})

        imitation = clone(model, interface, demonstrations, args.imitation_epochs,
                          args.seed, after_epoch=keep_early, keep_best=args.imitation_keep_best)
        imitation["early_model"] = f"after {early_epoch} of {args.imitation_epochs} behaviour-cloning epochs"
    log_std_final = args.log_std_final
    if log_std_final is not None:
        model.policy.log_std.requires_grad_(False)  # set by the schedule at each rollout (Curve)
    warmup = args.critic_warmup
    validation = validation_scenario(scenario, args.validation_seasons, args.seed)
    seasons = np.arange(args.validation_seasons)
    terms = draw_terms(validation, seasons, 1234)
    default_rule = WaterBudgetRule(FarmFacts.of_scenario(scenario))
    rule_return = float(run_episodes(default_rule, validation, seasons, seed=1000, terms=terms).episode_return.mean())
    # the residual's starting point (a separate rule object: the training environment's keeps its own state)
    tuned_rule_return = (None if rule is None else float(run_episodes(
        tuned_rule(scenario.name), validation, seasons, seed=1000, terms=terms).episode_return.mean()))
    config = {"task": scenario.name, "algorithm": args.algorithm, "history": args.history, "seed": args.seed,
              "timesteps": args.timesteps, "training_seasons": scenario.n_seasons, "n_envs": args.n_envs,
              "critic_warmup_steps": warmup, "log_std_final": log_std_final, "net_arch": net_arch, "action_kind": action_kind,
              "action": (f"a in [-1, 1] -> (a + 1) / 2 x {ACTION_SCALE_MM:g} mm" if rule is None else
                         f"a in [-1, 1] -> clip(the rule's mm + a x {RESIDUAL_SPAN_MM:g} mm, 0, {ACTION_SCALE_MM:g} mm); "
                         f"the network also sees the rule's mm / {RESIDUAL_SPAN_MM:g}"),
              **({} if rule is None else {"rule": {**rule_record(rule), "file": rule_file(scenario.name).name}}),
              **({} if imitation is None else {"imitation": imitation}),
              **({} if paw_filter is None else {"paw_filter": paw_filter.record()}),
              **({} if outlook is None else {"outlook": outlook.record()}),
              **({} if hindsight is None else {"critic_hindsight": {
                  **hindsight.record(), "use": "the value network's extra inputs in training; the policy files "
                                               "hold the policy alone (a fresh, untrained value network)"}}),
              "scaler": scaler.record(),
              "reward": f"task reward USD/ha / {REWARD_SCALE_USD:g} + potential shaping (value of the yield so far)",
              "hyper_parameters": hyper_parameters(args)}

    def save(model_, name: str, at: int) -> Path:
        path = out / f"{name}.zip"
        if hindsight is not None:  # the actor alone, in the headline agent's container
            from .asymmetric import actor_container
            model_ = actor_container(model_, interface.input_size, policy_kwargs, exploration(args.sde))
        model_.save(path)
        path.with_suffix(".json").write_text(json.dumps({**config, "timesteps_at_save": at}, indent=1) + "\n")
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
        tuned = "" if tuned_rule_return is None else f", tuned rule {tuned_rule_return:.1f}"
        print(f"[{row['timesteps']:>9}] {row['wall_s']:>6.0f} s  validation return {row['validation_return']:.1f}"
              f" (default rule {rule_return:.1f}{tuned}), water {row['validation_water_mm']:.0f} mm",
              file=sys.stderr, flush=True)

    def training_starts() -> None:
        nonlocal started
        if started is None:  # (a critic warm-up trains in two calls)
            started = time.perf_counter()
            print(f"training starts {started - launched:.1f} s after launch", file=sys.stderr, flush=True)

    early_at = max(args.n_envs * args.n_steps, args.timesteps // 100)
    if imitation is not None:
        cloned = {k: v.clone() for k, v in model.policy.state_dict().items()}
        model.policy.load_state_dict(early_weights)
        save(model, "early_model", 0)
        model.policy.load_state_dict(cloned)
    from stable_baselines3.common.callbacks import BaseCallback

    class Curve(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next_eval = 0
            self.early_saved = imitation is not None  # saved already: 1 % of the cloning

        def _on_training_start(self) -> None:
            training_starts()

        def _on_rollout_start(self) -> None:
            if log_std_final is not None:
                done = min(1.0, self.num_timesteps / args.timesteps)
                set_exploration(self.model, args.log_std_init + (log_std_final - args.log_std_init) * done)

        def _on_step(self) -> bool:
            if not self.early_saved and self.num_timesteps >= early_at:
                self.early_saved = True
                save(self.model, "early_model", self.num_timesteps)
                checkpoint(self.model, self.num_timesteps)
            if self.num_timesteps >= self.next_eval:
                self.next_eval += args.eval_freq
                checkpoint(self.model, self.num_timesteps)
            return True

    if args.algorithm in ("es", "grpo"):
        from .evolution import evolve
        from .grpo import grpo

        def own_loop_checkpoint(steps: int, early: bool) -> None:
            if early and imitation is None:  # (after cloning, the 1 % policy is the cloning's, saved above)
                save(model, "early_model", steps)
            checkpoint(model, steps)

        training_starts()
        steps_run = (evolve if args.algorithm == "es" else grpo)(model, interface, scenario, args, own_loop_checkpoint)
    else:
        callback = Curve()
        if warmup:
            with frozen_actor(model.policy):
                model.learn(total_timesteps=warmup, callback=callback, progress_bar=not args.no_progress)
        # (continuing: the learning-rate schedule runs on over the whole --timesteps)
        model.learn(total_timesteps=args.timesteps - model.num_timesteps, callback=callback,
                    progress_bar=not args.no_progress, reset_num_timesteps=not warmup)
        steps_run = int(model.num_timesteps)
    training_s = time.perf_counter() - started
    checkpoint(model, steps_run)
    save(model, "final_model", steps_run)
    with open(out / "learning_curve.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    selected = select_model(out)
    summary = {**config, "steps_run": steps_run, "selected": selected, "training_wall_s": round(training_s, 1),
               "total_wall_s": round(time.perf_counter() - launched, 1), "default_rule_validation_return": rule_return,
               **({} if tuned_rule_return is None else {"tuned_rule_validation_return": tuned_rule_return}),
               "final": rows[-1], "command": "crop-sim " + " ".join(sys.argv[1:])}
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(f"ran {steps_run} steps ({args.timesteps} asked) in {training_s:.0f} s of training, "
          f"{summary['total_wall_s']:.0f} s in all; wrote {out}", file=sys.stderr)
    return summary
