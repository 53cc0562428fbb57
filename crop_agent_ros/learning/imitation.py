"""Learning from a causal planner (the "MPC" below): its demonstrations, and behaviour cloning of a family
agent's network.

The causal planners (:mod:`crop_agent_ros.policies.family_mpc`, :mod:`crop_agent_ros.policies.family_hindsight`)
irrigate better than the tuned rules, but they plan with SIMPLE on every decision (seconds of CPU per field
and decision). A network that imitates it acts
in microseconds and reads only the observation. This is the **imitation variant** of the family agents (not
the headline agent, which learns from the reward alone): ``crop-sim demonstrate`` records the MPC's actions on
generated training seasons, and ``crop-sim train --task T --imitate FILES`` fits the PPO network's policy to
them before (optional) PPO fine-tuning on the reward.

    crop-sim demonstrate --task benton-quota --seasons 0..99 [--method expected-value|hindsight-value|mean-plan]
        [--scenarios K] [--decision-every-days 7] [--action-noise-mm 1.0] [--seed 0] --out demos/benton-quota-0.npz
    crop-sim demonstrate --task benton-sensing --labels-from demos/benton-quota-0.npz --out demos/benton-sensing-0.npz

Demonstrations: the planner (by default the expected-value one; the teachers of earlier runs with ``--method
hindsight-value`` or ``mean-plan``) runs on training seasons of the task's own pool (generated weather, the seasons the
agents train on; never a validation or evaluation season; for a task on several climates, the same positions
of each climate's pool, each field planning with its own climate's continuations) with the task's terms drawn
per season by the environment (``--seed``). To show the network states off the MPC's own path (Laskey et al.
2017, DART), the executed amount on days the MPC irrigates is its amount plus Gaussian noise of
``--action-noise-mm`` (cut at 0); the label is always the MPC's own amount for the state reached. With
``--behaviour POLICY.zip`` a trained agent acts instead and the MPC labels the states the agent reaches (one
round of DAgger, Ross et al. 2011). The planners read no PAW sensor: with ``--labels-from FILE`` a planner's
file of one task is re-run on a task that differs from it only in its sensor, with the file's labels and this
task's observations, without planning (:class:`_LabelsOfFile`). A file holds the observations (S, 29) and
labels (S,) mm of every live field-day, the season and day of each, and how they were made.

Behaviour cloning (:func:`clone`): the actor's mean action a (the network's input as the agent sees it, the
normalised observation, or the last k of them with ``--history k``) is fitted to a* = mm / 12.5 - 1 (the
agent's a in [-1, 1] -> (a + 1) / 2 x 25 mm) by squared error, one-sided where a* sits on a bound (a* = -1,
no water: any a <= -1 is exact, since the action is clipped there). A tenth of the seasons is held out of the
fit to report its error (mean absolute, mm); with ``--imitation-keep-best`` the fit ends with the epoch whose
error there was least (early stopping; else the last epoch).
"""

from __future__ import annotations

import copy
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from crop_sim_ros.usage import UsageError, user_input

from .agent import ACTION_SCALE_MM

FORMAT = "crop-sim demonstrations 1"


class _Recorder:
    """Wraps the MPC in :func:`crop_agent_ros.policies.rollout.run_episodes`: records (observation, the MPC's
    mm) of every live field and returns the MPC's mm with noise on wet days, or, with a ``behaviour`` policy,
    that policy's mm (DAgger: the MPC labels the states the behaviour policy visits)."""

    def __init__(self, mpc, noise_mm: float, seed: int, behaviour=None):
        self.mpc = mpc
        self.behaviour = behaviour
        self.name = "mpc-recorder"
        self.noise_mm = noise_mm
        self.rng = np.random.default_rng(seed)
        self.observations, self.labels, self.fields = [], [], []

    def reset(self, seed=None):
        self.mpc.reset(seed)
        if self.behaviour is not None:
            self.behaviour.reset(seed)

    def begin_season(self, contexts):
        self.mpc.begin_season(contexts)
        if self.behaviour is not None:  # an agent with a climate outlook reads its fields' climates
            self.behaviour.begin_season(contexts)

    def act(self, obs):
        label = np.asarray(self.mpc.act(obs), dtype=float)
        live = self.mpc.live
        self.observations.append(obs[live].astype(np.float32))
        self.labels.append(label[live])
        self.fields.append(np.flatnonzero(live))
        if self.behaviour is not None:
            return np.asarray(self.behaviour.act(obs), dtype=float)
        noise = self.rng.normal(0.0, self.noise_mm, len(label)) if self.noise_mm > 0 else 0.0
        return np.where(label > 0.0, np.maximum(label + noise, 0.0), 0.0)


class _LabelsOfFile:
    """A teacher that does not plan: on each live field-day it gives the label a demonstrations file holds for
    that (season, day). The planners read no PAW sensor, so a task that differs from the file's only in its
    sensor (``benton-sensing`` and ``benton-quota``: same weather, same terms drawn from the same seed) has the
    same labels on the same seasons with the same seed and executed noise; only the observations differ.
    Every field-day is checked against the file on the observation values no sensor touches (thermal time,
    day, today's weather, the terms, the quota left, yesterday's irrigation, ET0): a task whose states differ
    is refused (ValueError naming the first field-day and value that differ), as is a file whose field-days
    this run does not all reach."""

    # Columns that depend only on the weather, the terms and the water applied: equal on the two tasks.
    EXACT = ("thermal_time_degc_d", "days_since_sowing", "tmax_degc", "tmin_degc", "tavg_degc", "rain_mm",
             "srad_mj_m2", "co2_ppm", "vap_hpa", "wind_m_s", "tuber_price_usd_per_t", "water_cost_usd_per_mm",
             "event_cost_usd", "quota_remaining_mm", "season_days_left", "capacity_mm_per_day",
             "irrigation_yesterday_mm", "et0_mm")

    def __init__(self, path: str, data: dict, pool_seasons: np.ndarray):
        from crop_sim_ros.task.layout import EXTENDED
        self.path, self.pool_seasons = path, pool_seasons
        self.columns = [EXTENDED.index(name) for name in self.EXACT]
        self.row_of = {(int(s), int(d)): row for row, (s, d) in enumerate(zip(data["season"], data["day"]))}
        self.observations, self.mm = data["observations"], data["mm"]
        self.settings = json.loads(str(data["settings"]))
        self.day, self.used = 0, 0

    def reset(self, seed=None):
        self.day, self.used = 0, 0

    def begin_season(self, contexts):
        pass

    def describe(self) -> dict:
        return {**{k: v for k, v in self.settings.items() if k != "wall_s"}, "labels_from": self.path}

    def act(self, obs):
        rows = np.array([self.row_of.get((int(s), self.day), -1) for s in self.pool_seasons])
        self.live = rows >= 0
        mine = np.asarray(obs, dtype=np.float32)[self.live][:, self.columns]
        theirs = self.observations[rows[self.live]][:, self.columns]
        differ = mine != theirs
        if differ.any():
            field, column = np.argwhere(differ)[0]
            raise ValueError(f"season {self.pool_seasons[self.live][field]}, day {self.day}: "
                             f"{self.EXACT[column]} is {mine[field, column]:g} here and {theirs[field, column]:g} in "
                             f"the file (the file's task does not share this task's weather, terms or actions)")
        self.used += int(self.live.sum())
        self.day += 1
        return np.where(self.live, self.mm[np.maximum(rows, 0)], 0.0)

    def check_complete(self):
        if self.used != len(self.mm):
            raise ValueError(f"this run reached {self.used} of the file's {len(self.mm)} field-days "
                             f"(the file's task ends its seasons on other days)")


def demonstrate(task_name: str, seasons: np.ndarray, settings, action_noise_mm: float, seed: int,
                behaviour_path: str | None = None) -> dict:
    """The MPC's demonstrations on ``seasons`` of ``task_name``'s training pool (of each climate of a mixture:
    its pool index is the file's ``season``; see the module docstring); with ``behaviour_path`` (a family
    agent's policy file of this task), on the states that agent visits."""
    from ..policies.family_mpc import continuation_pool, planner
    from ..policies.family_oracle import TaskConstants
    scenario, pool_seasons = _training_seasons(task_name, seasons)
    mpc = planner(TaskConstants.of_scenario(scenario), continuation_pool(scenario, settings.scenarios), settings)
    behaviour = None
    if behaviour_path is not None:
        from .agent import LearnedPolicy
        with user_input(f"--behaviour {behaviour_path}", (OSError, ValueError, KeyError)):
            behaviour = LearnedPolicy(behaviour_path, name="behaviour")
        if behaviour.config.get("task") != task_name:
            raise UsageError(f"--behaviour {behaviour_path}: trained on {behaviour.config.get('task')!r}, not {task_name!r}")
    return _record(task_name, scenario, seasons, pool_seasons, mpc, action_noise_mm, seed, behaviour_path, behaviour)


def demonstrate_with_labels_of(task_name: str, path: str) -> dict:
    """The demonstrations of ``path`` (a planner's file, not a DAgger one) re-run on ``task_name``: the same
    seasons, seed and executed noise, the file's labels (:class:`_LabelsOfFile`; no planning), this task's
    observations. For a task that differs from the file's only in its PAW sensor (the planners read none)."""
    with user_input(f"--labels-from {path}", (OSError, ValueError, KeyError)):
        data = _read(path, ("observations", "mm", "season", "day", "settings"))
        made = json.loads(str(data["settings"]))
        if made.get("behaviour") is not None:
            raise ValueError(f"its states are those {made['behaviour']} visited reading its own task's observations "
                             f"(DAgger): they cannot be re-run on another task")
        seasons = np.arange(made["seasons"][0], made["seasons"][1] + 1)
    scenario, pool_seasons = _training_seasons(task_name, seasons)
    teacher = _LabelsOfFile(path, data, pool_seasons)
    with user_input(f"--labels-from {path}", (ValueError,)):
        demonstrations = _record(task_name, scenario, seasons, pool_seasons, teacher, made["action_noise_mm"],
                                 made["seed"], None, None)
        teacher.check_complete()
    return demonstrations


def _training_seasons(task_name: str, seasons: np.ndarray):
    """The family task and the pool indices of training positions ``seasons`` (UsageError if not a family task
    on generated weather or out of its pool)."""
    from crop_sim_ros.task.scenario import get_scenario
    from ..policies.family_tuning import of_each_part
    scenario = get_scenario(task_name)
    if not scenario.is_family_task or scenario.weather.kind not in ("generator", "mixture"):
        raise UsageError(f"--task: demonstrations need a family task trained on generated weather; {task_name!r} "
                         f"is {'not a family task' if not scenario.is_family_task else 'on ' + scenario.weather.kind}")
    with user_input(None, (ValueError,)):  # the message names --seasons
        return scenario, of_each_part(scenario, seasons)


def _record(task_name, scenario, seasons, pool_seasons, teacher, action_noise_mm, seed, behaviour_path, behaviour):
    from ..policies.base import DAYS_SINCE_SOWING
    from ..policies.rollout import run_episodes
    recorder = _Recorder(teacher, action_noise_mm, seed, behaviour)
    began = time.perf_counter()
    episodes = run_episodes(recorder, scenario, pool_seasons, seed=seed)
    observations = np.concatenate(recorder.observations)
    return {"format": FORMAT, "task": task_name, "observations": observations,
            "mm": np.concatenate(recorder.labels), "season": pool_seasons[np.concatenate(recorder.fields)],
            "day": np.rint(observations[:, DAYS_SINCE_SOWING]).astype(np.int64), "episode_return_usd_ha": episodes.episode_return,
            "settings": json.dumps({**teacher.describe(), "action_noise_mm": action_noise_mm,
                                    "seed": seed, "behaviour": behaviour_path, "seasons": [int(seasons.min()), int(seasons.max())],
                                    "wall_s": round(time.perf_counter() - began, 1)})}


def _read(path: str, keys: tuple[str, ...]) -> dict:
    """The arrays ``keys`` of demonstrations file ``path`` (ValueError if it is not one; OSError/KeyError as
    numpy raises them)."""
    with np.load(path) as data:
        if str(data["format"]) != FORMAT:
            raise ValueError(f"not a demonstrations file ({FORMAT!r})")
        return {k: data[k] for k in keys}


def serves(file_task: str, task_name: str) -> bool:
    """Whether demonstrations recorded on task ``file_task`` train task ``task_name``: the same task, or one that
    differs from it only in holding more weather parts (same crop, soil, terms, quota, noise; each generated
    part of ``file_task`` one of ``task_name``'s) and, possibly, in the irrigation system's capacity. Its
    field-days are then states of ``task_name`` too, with the teacher's labels (``climates-quota``'s and
    ``benton-early-quota``'s files train ``climates3-quota``); a file on another pivot size holds states of the
    same decision with another value in the observation's ``capacity_mm_per_day`` column, the teacher planning
    within that capacity (``benton-early-pivot``'s 5.5 mm/d files train ``climates3-quota``, 8 mm/d: a regime,
    demand above what the system applies, that its own training climates never reach)."""
    if file_task == task_name:
        return True
    from crop_sim_ros.task.scenario import generated_parts, get_scenario
    try:
        recorded, task = get_scenario(file_task), get_scenario(task_name)
        recorded_parts, task_parts = generated_parts(recorded), generated_parts(task)
    except (KeyError, ValueError):
        return False
    neutral = {"name": task.name, "description": task.description, "weather": task.weather,
               "sowing_date": task.sowing_date,
               "limits": replace(recorded.limits, capacity_mm_per_day=task.limits.capacity_mm_per_day)}
    return replace(recorded, **neutral) == task and all(part in task_parts for part in recorded_parts)


def _season_climates(task_name: str, seasons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The climate and sowing day of the year of each row's season (a position of ``task_name``'s pool): what
    a climate outlook (:mod:`crop_agent_ros.policies.outlook`) reads."""
    from crop_sim_ros.task.scenario import get_scenario
    from ..policies.outlook import pool_climates
    pool = pool_climates(get_scenario(task_name))
    if len(seasons) and int(np.max(seasons)) >= len(pool):
        raise ValueError(f"season {int(np.max(seasons))} is not in {task_name}'s pool of {len(pool)} seasons")
    climates = np.array([pool[int(s)][0] for s in seasons], dtype=object)
    return climates, np.array([pool[int(s)][1] for s in seasons], dtype=int)


def load_demonstrations(patterns: list[str], task_name: str) -> dict:
    """The demonstration files matching ``patterns`` (globs), concatenated; each must be of ``task_name`` or of a
    task whose demonstrations serve it (:func:`serves`)."""
    import glob
    paths = sorted({p for pattern in patterns for p in glob.glob(pattern)})
    if not paths:
        raise UsageError(f"--imitate: no demonstration file matches {' '.join(patterns)}")
    parts = []
    for number, path in enumerate(paths):
        with user_input(f"--imitate {path}", (OSError, ValueError, KeyError)):
            data = _read(path, ("task", "observations", "mm", "season", "day"))
            if not serves(str(data["task"]), task_name):
                raise ValueError(f"demonstrations of {str(data['task'])!r}, a task that differs from {task_name!r} "
                                 "in more than holding fewer of its weather parts (and its pivot's capacity)")
            part = {k: data[k] for k in ("observations", "mm", "season", "day")}
            part["file"] = np.full(len(part["mm"]), number)
            part["climate"], part["sowing_day"] = _season_climates(str(data["task"]), part["season"])
        if not (np.all(np.isfinite(part["observations"])) and np.all(np.isfinite(part["mm"]))
                and np.all(part["mm"] >= 0.0)):
            raise UsageError(f"--imitate {path}: observations and mm must be finite, mm >= 0")
        parts.append(part)
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} | {"files": paths}


def network_inputs(interface, demonstrations: dict) -> tuple[np.ndarray, np.ndarray]:
    """(S, input_size) network inputs of the demonstrations as the agent would have seen them, and the order
    of the samples they are in. With a history of k days each input is the last k scaled observations of the
    same season of the same file, newest last, a season's first observation repeated before its start (as
    :class:`~crop_agent_ros.learning.agent.History` stacks them); with a soil-water filter, the filter's
    estimate after the season's observations up to that day; a season's days must run 0, 1, 2, ..."""
    raw = demonstrations["observations"].astype(float)
    k = interface.history.k
    order = np.lexsort((demonstrations["day"], demonstrations["season"], demonstrations["file"]))
    outlook = None
    if interface.outlook is not None:
        from ..policies.outlook import features
        outlook = features(demonstrations["climate"][order], demonstrations["sowing_day"][order], raw[order])
    if k == 1 and interface.paw_filter is None:
        return interface.network_input(interface.scaler(raw[order]), None, None, outlook), order
    day = demonstrations["day"][order]
    episode = np.stack([demonstrations["file"][order], demonstrations["season"][order]])
    starts = np.r_[True, np.any(episode[:, 1:] != episode[:, :-1], axis=0)]
    first_row = np.maximum.accumulate(np.where(starts, np.arange(len(day)), 0))
    broken = day != np.arange(len(day)) - first_row
    if broken.any():
        row = order[np.argmax(broken)]
        needs = f"a history of {k} days" if k > 1 else "the soil-water filter"
        raise UsageError(f"--imitate: season {demonstrations['season'][row]} of "
                         f"{demonstrations['files'][demonstrations['file'][row]]} does not hold consecutive days from "
                         f"day 0 ({needs} needs them)")
    rows, ordered = np.arange(len(day)), interface.scaler(raw[order])
    lagged = [ordered[rows - np.minimum(lag, day)] for lag in range(k - 1, -1, -1)]  # oldest first
    paw_mm = None
    if interface.paw_filter is not None:
        paw_mm = _filtered(interface.paw_filter, raw[order], np.cumsum(starts) - 1, day)
    return interface.network_input(np.concatenate(lagged, axis=1), paw_mm, None, outlook), order


def _filtered(paw_filter, raw: np.ndarray, episode: np.ndarray, day: np.ndarray) -> np.ndarray:
    """The filter's estimate (mm) on each row of ``raw`` (rows grouped by ``episode`` 0..E-1, each's days
    0, 1, 2, ... in order): all episodes run at once as the filter's fields, one day per update (an episode
    that has ended repeats its last row, whose estimates are not used)."""
    episodes, days = int(episode[-1]) + 1, int(day.max()) + 1
    grid = np.full((episodes, days), -1)
    grid[episode, day] = np.arange(len(day))
    last = np.maximum.accumulate(grid, axis=1)  # an ended episode's last row
    running = copy.deepcopy(paw_filter)
    running.reset()
    estimate = np.empty(len(day))
    for d in range(days):
        present = grid[:, d] >= 0
        today = running.update(raw[last[:, d]])
        estimate[grid[present, d]] = today[present]
    return estimate


def clone(model, interface, demonstrations: dict, epochs: int, seed: int, learning_rate: float = 1e-3,
          batch_size: int = 256, log=print, after_epoch=None, keep_best: bool = False) -> dict:
    """Fit ``model``'s actor mean (an SB3 PPO ``MlpPolicy``) to the demonstrations (module docstring); the
    critic and the log-std are left as they are; ``after_epoch(epoch)`` is called after each epoch (1-based).
    ``keep_best``: the actor ends with the weights of the epoch whose held-out error was least (early stopping:
    on noisy observations, e.g. ``benton-sensing``'s, the held-out error rises after a few tens of epochs as
    the fit learns the training seasons' noise), else with the last epoch's. Returns the fit's error on
    held-out seasons (mm) and the epoch it was reached at."""
    import torch
    if interface.action_kind != "mm":
        raise UsageError("--imitate: behaviour cloning fits the mm action (--action mm)")
    inputs, order = network_inputs(interface, demonstrations)
    target = np.clip(demonstrations["mm"][order] / (ACTION_SCALE_MM / 2.0) - 1.0, -1.0, 1.0).astype(np.float32)
    seasons = np.unique(demonstrations["season"])
    rng = np.random.default_rng(seed)
    held = rng.choice(seasons, size=len(seasons) // 10, replace=False)
    test = np.isin(demonstrations["season"][order], held)
    checked = test if held.size else ~test  # fewer than 10 seasons: none held out, the error is the fit's
    policy = model.policy
    actor = list(policy.mlp_extractor.policy_net.parameters()) + list(policy.action_net.parameters())
    optimiser = torch.optim.Adam(actor, lr=learning_rate)
    x_fit, y_fit = torch.as_tensor(inputs[~test]), torch.as_tensor(target[~test])
    x_test, y_test = torch.as_tensor(inputs[checked]), torch.as_tensor(target[checked])
    generator = torch.Generator().manual_seed(seed)

    def mean_action(x):
        return policy.action_net(policy.mlp_extractor.forward_actor(policy.extract_features(x))).squeeze(-1)

    def loss_of(a, y):
        error = torch.where(y <= -1.0, torch.relu(a - y), torch.where(y >= 1.0, torch.relu(y - a), a - y))
        return (error ** 2).mean()

    def test_error_mm():
        with torch.no_grad():
            a = torch.clamp(mean_action(x_test), -1.0, 1.0)
        return float(torch.mean(torch.abs(a - y_test))) * ACTION_SCALE_MM / 2.0

    error_on = "held-out seasons'" if held.size else "training samples' (fewer than 10 seasons: none held out)"
    began = time.perf_counter()
    before = test_error_mm()
    best = (np.inf, 0, None)  # (held-out error mm, epoch, the actor's weights)
    for epoch in range(epochs):
        order = torch.randperm(len(x_fit), generator=generator)
        for first in range(0, len(order), batch_size):
            batch = order[first:first + batch_size]
            loss = loss_of(mean_action(x_fit[batch]), y_fit[batch])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
        if after_epoch is not None:
            after_epoch(epoch + 1)
        if keep_best and (error := test_error_mm()) < best[0]:
            best = (error, epoch + 1, [w.detach().clone() for w in actor])
        if (epoch + 1) % max(1, epochs // 5) == 0:
            log(f"behaviour cloning: epoch {epoch + 1}/{epochs}, {error_on} mean abs error {test_error_mm():.2f} mm",
                file=sys.stderr)
    if keep_best:
        with torch.no_grad():
            for weight, kept in zip(actor, best[2]):
                weight.copy_(kept)
        log(f"behaviour cloning: kept epoch {best[1]} (the least held-out error)", file=sys.stderr)
    return {"files": [str(p) for p in demonstrations["files"]], "samples": int(len(x_fit)),
            "held_out_samples": int(test.sum()), "held_out_seasons": sorted(int(s) for s in held),
            "epochs": epochs, "kept_epoch": best[1] if keep_best else epochs, "learning_rate": learning_rate,
            "batch_size": batch_size,
            "error_on": error_on, "abs_error_mm_before": round(before, 3), "abs_error_mm": round(test_error_mm(), 3),
            "wall_s": round(time.perf_counter() - began, 1)}


# --- crop-sim demonstrate ----------------------------------------------------------------------------------

def add_arguments(parser) -> None:
    from ..policies.family_mpc import METHODS
    parser.add_argument("--task", required=True, help="a family task on generated weather (e.g. benton-quota)")
    parser.add_argument("--seasons", help="training-pool seasons 'A..B' (of each climate of a mixture); required "
                                          "unless --labels-from")
    parser.add_argument("--method", choices=METHODS,
                        help=f"the teacher: a causal planner of crop_agent_ros.policies.family_mpc (default {METHODS[0]})")
    parser.add_argument("--scenarios", type=int, help="planner: weather continuations per decision (default: the "
                                                       "planner's, 4 for hindsight-value and expected-value, 8 for "
                                                       "mean-plan)")
    parser.add_argument("--decision-every-days", type=int, help="planner: days between decisions (default: 7)")
    parser.add_argument("--action-noise-mm", type=float,
                        help="std of the noise added to the executed amount on wet days (mm; default 1.0)")
    parser.add_argument("--seed", type=int, help="seed of the terms, the noise and the sensor noise (default 0)")
    parser.add_argument("--behaviour", default=None,
                        help="a family agent's policy file of this task: it acts, the MPC labels the states it visits "
                             "(DAgger; --action-noise-mm is then unused)")
    parser.add_argument("--labels-from", default=None, metavar="FILE",
                        help="no planning: re-run a planner's demonstrations file (its seasons, seed, noise and "
                             "labels) on --task, a task that differs from the file's only in its PAW sensor "
                             "(benton-sensing from benton-quota); every state is checked against the file")
    parser.add_argument("--out", required=True, help="demonstrations file (.npz)")


def run(args) -> int:
    from ..policies.family_mpc import METHODS, planner_settings
    from ..policies.family_oracle import season_range
    if args.labels_from is not None:
        given = [flag for flag, value in (("--seasons", args.seasons), ("--method", args.method),
                                          ("--scenarios", args.scenarios), ("--decision-every-days", args.decision_every_days),
                                          ("--action-noise-mm", args.action_noise_mm), ("--seed", args.seed),
                                          ("--behaviour", args.behaviour)) if value is not None]
        if given:
            raise UsageError(f"--labels-from: the seasons, seed, noise and teacher are the file's; drop {', '.join(given)}")
        data = demonstrate_with_labels_of(args.task, args.labels_from)
    else:
        if args.seasons is None:
            raise UsageError("--seasons is required (unless --labels-from)")
        with user_input(None, (ValueError,)):  # the message names --seasons
            seasons = season_range(args.seasons)
        noise_mm = 1.0 if args.action_noise_mm is None else args.action_noise_mm
        if not (np.isfinite(noise_mm) and noise_mm >= 0):
            raise UsageError(f"--action-noise-mm: expected a number >= 0, got {noise_mm}")
        with user_input("--scenarios / --decision-every-days", (ValueError,)):
            settings = planner_settings(args.method or METHODS[0], args.scenarios, args.decision_every_days)
        data = demonstrate(args.task, seasons, settings, noise_mm, 0 if args.seed is None else args.seed, args.behaviour)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out, **data)
    actor = ("the behaviour policy" if args.behaviour else
             f"the file's actions on {args.task}" if args.labels_from else "the planner with its noise")
    print(f"{len(data['mm'])} field-days of {len(np.unique(data['season']))} seasons -> {out}; return of {actor} "
          f"{data['episode_return_usd_ha'].mean():,.0f} USD/ha; {json.loads(data['settings'])['wall_s']} s")
    return 0
