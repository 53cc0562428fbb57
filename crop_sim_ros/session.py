"""A farm session: one field's seasons served to clients, as plain Python under the simulator node.

The node (:mod:`crop_sim_ros.sim`) is wiring: parameters, topics, services, the season log, timers. What a
client's command or step does to the farm is decided here, with no ROS import, as ``task/core.py`` decides
under ``task/env.py``:

===================== ==================================================================================
Call                  What it does
===================== ==================================================================================
``command(values)``   checks a command ``[day, mm]`` or ``[day, mm, episode]`` against the current day,
                      episode and limits; an accepted one becomes today's pending command. Returns a
                      :class:`CommandOutcome` (accepted, or refused with a reason; ``timing``: only
                      too early, too late or for another episode)
``step()``            advances one day with the pending command for today (none: 0 mm). Returns a
                      :class:`StepOutcome`; after the season ended, or if the environment refuses, an
                      outcome with ``error`` and the session as it was
``reset(env, ...)``   starts the next episode on ``env`` (the same environment or a rebuilt one); if the
                      environment's reset fails, the exception goes to the caller and the current season
                      stays as it was
===================== ==================================================================================

State (read by the node for its topics, log and its status on /diagnostics):

======================== ====== ==============================================================================
Name                     Unit   Description
======================== ====== ==============================================================================
episode                  1      episodes started since the node started (0 before the first reset)
day                      d      days since sowing of the current season
ended, end_reason        -      whether the season is over, and why ("crop mature on day 131", ...)
obs                      -      today's observation (the scenario's layout: 20 or 29 values)
episode_return           *      sum of the season's rewards (t/ha, or USD/ha for a family task)
sowing                   date   the season's sowing date
seed, weather_season     -      the reset's seed (None: unseeded) and the weather season drawn
terms                    -      the season's farm terms in ``ros_interface.FarmTerms`` order (no episode)
max_mm                   mm/d   the largest command accepted (the scenario's action bound)
pending                  -      (day, mm, sequence) of today's accepted command, or None
commands_received        1      commands received since the start (accepted + rejected)
commands_accepted        1      of which accepted
commands_rejected        1      of which rejected
days_without_command     d      days of this season stepped without a command
======================== ====== ==============================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import date

import numpy as np

from .task import IrrigationEnv

FREE_RUNNING_STEP_REFUSAL = "mode is free_running: the node steps by itself; use ~/irrigation"


@dataclass(frozen=True)
class CommandOutcome:
    """What became of one command: ``text`` is "accepted ..." or "rejected: <why>"."""

    accepted: bool
    text: str
    timing: bool  # refused only for its timing (a past or future day, another episode, an ended season)
    day: float  # as commanded (NaN if missing)
    mm: float
    sequence: int
    current_day: int


@dataclass(frozen=True)
class StepOutcome:
    """One day stepped (``error`` None), or why not (``error``; nothing changed)."""

    error: str | None
    episode: int
    day: int  # after the step (the error's: the current day)
    day_before: int = -1
    obs_before: np.ndarray | None = None
    obs: np.ndarray | None = None
    info: dict | None = None
    requested_mm: float = 0.0
    applied_mm: float = 0.0
    reward: float = 0.0
    terminated: bool = False
    truncated: bool = False
    yield_t_ha: float = 0.0  # the season's yield on its last day, else 0
    sequence: int = -1  # the command applied (-1: none, 0 mm)
    environment_failed: bool = False  # the error came from the environment (not an ended season)

    @property
    def ok(self) -> bool:
        return self.error is None

    @property
    def cut(self) -> bool:
        """The capacity or the quota applied less than the command asked (it was within the action bound)."""
        return self.ok and self.applied_mm < self.requested_mm


class FarmSession:
    """One field's seasons, its commands and counters (see the module docstring)."""

    def __init__(self, env: IrrigationEnv):
        self.env = env
        self.max_mm = float(env.scenario.max_irrigation_mm)
        self.episode = 0
        self.day = 0
        self.ended = True
        self.end_reason = "no season yet"
        self.episode_return = 0.0
        self.obs: np.ndarray | None = None
        self.seed: int | None = None
        self.weather_season = -1
        self.sowing = date(2000, 1, 1)
        self.terms: tuple[float, ...] = ()
        self.pending: tuple[int, float, int] | None = None
        self.commands_received = 0
        self.commands_accepted = 0
        self.commands_rejected = 0
        self.days_without_command = 0

    # --- commands ----------------------------------------------------------------------------------------

    def check_command(self, values: list) -> tuple[str | None, bool]:
        """(why this command [day, mm] or [day, mm, episode] is refused, or None; whether it is only a question
        of timing: a past or future day, another episode, a season that ended)."""
        day = values[0] if values else math.nan
        mm = values[1] if len(values) > 1 else math.nan
        if len(values) not in (2, 3):
            return f"expected [day, mm] or [day, mm, episode], got {len(values)} values", False
        if not (math.isfinite(day) and day == int(day)):
            return f"day {day!r} is not a whole number", False
        if len(values) == 3 and values[2] != self.episode:
            return f"episode {values[2]!r} is not the current episode {self.episode}", True
        if self.ended:
            return self._ended_text(), True
        if day < self.day:
            return f"day {int(day)} is past: the current day is {self.day}", True
        if day > self.day:
            return f"day {int(day)} is in the future: the current day is {self.day}", True
        if not math.isfinite(mm):
            return f"irrigation {mm!r} mm is not a finite number", False
        if mm < 0.0:
            return f"irrigation {mm!r} mm is negative", False
        if mm > self.max_mm:
            return f"irrigation {mm!r} mm exceeds the limit of {self.max_mm:g} mm/day", False
        return None, False

    def command(self, values: list, and_step: bool = False, lockstep: bool = True) -> CommandOutcome:
        """Check a command; an accepted one becomes today's pending command (replacing an earlier one).
        ``and_step``: the client also asks for the step (refused unless ``lockstep``)."""
        self.commands_received += 1
        sequence = self.commands_received
        day = values[0] if values else math.nan
        mm = values[1] if len(values) > 1 else math.nan
        problem, timing = self.check_command(values)
        if problem is None and and_step and not lockstep:
            problem, timing = FREE_RUNNING_STEP_REFUSAL, False
        if problem is None:
            self.commands_accepted += 1
            self.pending = (self.day, float(mm), sequence)
            text = (f"accepted {mm:g} mm for day {self.day} (episode {self.episode})"
                    + (", stepping" if and_step else ""))
        else:
            self.commands_rejected += 1
            text = f"rejected: {problem}"
        return CommandOutcome(problem is None, text, timing, day, mm, sequence, self.day)

    # --- step --------------------------------------------------------------------------------------------

    def step(self) -> StepOutcome:
        """Advance one day with today's pending command (none: 0 mm); the pending command is used up either
        way."""
        if self.ended:
            return StepOutcome(self._ended_text(), self.episode, self.day)
        day, obs_before = self.day, self.obs
        mm, sequence = 0.0, -1
        if self.pending is not None and self.pending[0] == day:
            _, mm, sequence = self.pending
        self.pending = None
        try:
            obs, reward, terminated, truncated, info = self.env.step(mm)
        except Exception as error:  # noqa: BLE001 - the environment refused: state unchanged
            return StepOutcome(f"{type(error).__name__}: {error}", self.episode, self.day,
                               environment_failed=True)
        terminated, truncated = bool(terminated), bool(truncated)
        self.obs = obs
        self.day = int(info["day"])
        self.episode_return = float(info["episode_return"])
        if sequence < 0:
            self.days_without_command += 1
        if terminated or truncated:
            self.ended = True
            self.end_reason = (f"crop mature on day {self.day}" if terminated
                               else f"weather ran out on day {self.day}")
        return StepOutcome(None, self.episode, self.day, day, obs_before, obs, info,
                           info["irrigation_requested_mm"], info["irrigation_applied_mm"], float(reward), terminated,
                           truncated, info["yield_t_ha"] if terminated else 0.0, sequence)

    def _ended_text(self) -> str:
        return f"the season has ended ({self.end_reason}); call ~/reset"

    def cut_reason(self, outcome: StepOutcome) -> str:
        """Why a cut command (``outcome.cut``) was cut: the daily capacity or the season's quota."""
        params = self.env.params
        why = (f"the irrigation capacity of {params.capacity_mm_per_day:g} mm/d"
               if outcome.applied_mm == params.capacity_mm_per_day else
               f"the season's quota of {self.terms[3]:g} mm ({outcome.applied_mm:g} mm were left)")
        return (f"cut: {outcome.applied_mm:g} of the {outcome.requested_mm:g} mm commanded for day "
                f"{outcome.day_before} applied, by {why}")

    # --- reset -------------------------------------------------------------------------------------------

    def reset(self, env: IrrigationEnv, seed: int | None, weather_season: int | None) -> dict:
        """Start the next episode on ``env`` (``weather_season`` None: drawn); returns the environment's reset
        info. If ``env.reset`` raises, nothing changed."""
        options = {"season": weather_season} if weather_season is not None else None
        obs, info = env.reset(seed=seed, options=options)
        self.env = env
        self.max_mm = float(env.scenario.max_irrigation_mm)
        self.episode += 1
        self.seed = seed
        self.obs = obs
        self.weather_season = info["season"]
        self.day = int(info["day"])
        self.sowing = date.fromisoformat(info["date"])
        self.ended = False
        self.end_reason = ""
        self.episode_return = 0.0
        self.pending = None
        self.days_without_command = 0
        self.terms = self._season_terms(info)
        return info

    def _season_terms(self, info: dict) -> tuple[float, ...]:
        """The season's farm terms in ros_interface.FarmTerms order, without the episode."""
        params, max_mm = self.env.params, self.max_mm
        capacity = min(float(params.capacity_mm_per_day), max_mm)
        if not self.env.scenario.is_family_task:  # no money terms: the reward is in t/ha
            return (math.nan, math.nan, math.nan, math.inf, capacity)
        return (float(info["yield_value_per_t"]) * params.dry_matter_fraction, float(info["water_cost_per_mm"]),
                float(params.event_cost), float(info["quota_mm"]), capacity)
