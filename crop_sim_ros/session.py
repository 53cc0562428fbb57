"""A farm session: one field's seasons served to clients, as plain Python under the simulator node.

The node (:mod:`crop_sim_ros.sim`) is wiring: parameters, topics, services, the season log, timers. What a
client's command or step does to the farm is decided here, with no ROS import, as ``task/core.py`` decides
under ``task/env.py``:

===================== ==================================================================================
Call                  What it does
===================== ==================================================================================
``command(command)``  checks a :class:`Command` against the field, the current episode, day and its farm
                      time, and the limits; an accepted one becomes today's pending command. Returns a
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
field                    -      the field the session serves (the node's namespace, ``farm`` at the root)
episode                  1      episodes started since the node started (0 before the first reset)
day                      d      days since sowing of the current season
ended, end_reason        -      whether the season is over, and why ("crop mature on day 131", ...)
obs                      -      today's observation (the scenario's layout: 20 or 29 values)
episode_return           *      sum of the season's rewards (t/ha, or USD/ha for a family task)
sowing                   date   the season's sowing date
seed, weather_season     -      the reset's seed (None: unseeded) and the weather season drawn
terms                    -      the season's farm terms in ``ros_interface.FarmTerms`` order (no episode)
max_mm                   mm/d   the largest command accepted (the scenario's action bound)
pending                  -      (command, sequence) of today's accepted command, or None
commands_received        1      commands received since the start (accepted + rejected)
commands_accepted        1      of which accepted
commands_rejected        1      of which rejected
days_without_command     d      days of this season stepped without a command
======================== ====== ==============================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import date, timedelta

import numpy as np

from .task import IrrigationEnv

FREE_RUNNING_STEP_REFUSAL = "mode is free_running: the node steps by itself; use ~/irrigation"
ANY_EPISODE = -1  # a command's episode: valid in any (crop_sim_interfaces/msg/IrrigationCommand.ANY_EPISODE)
NS_PER_DAY = 86_400 * 10**9


def farm_time_ns(sowing: date, day: int) -> int:
    """Farm time of ``day``: midnight UTC of the sowing date plus ``day`` days, ns since 1970-01-01 UTC."""
    return ((sowing - date(1970, 1, 1)).days + day) * NS_PER_DAY


@dataclass(frozen=True)
class Command:
    """One irrigation command as received (crop_sim_interfaces/msg/IrrigationCommand without ROS types)."""

    day: int  # days since sowing of the day it is for
    mm: float  # the day's irrigation, mm
    episode: int = ANY_EPISODE  # the reset counter it is valid in; ANY_EPISODE: any
    stamp_ns: int = 0  # farm time of the day it is for, ns since 1970-01-01 UTC; 0: unstamped (not checked)
    field: str = ""  # the field it is for; '': any


@dataclass(frozen=True)
class CommandOutcome:
    """What became of one command: ``text`` is "accepted ..." or "rejected: <why>"."""

    accepted: bool
    text: str
    timing: bool  # refused only for its timing (a past or future day, another episode, an ended season)
    command: Command
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
    command: Command | None = None  # the command applied (None: none)
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

    def __init__(self, env: IrrigationEnv, field: str = "farm"):
        self.env = env
        self.field = field
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
        self.pending: tuple[Command, int] | None = None
        self.commands_received = 0
        self.commands_accepted = 0
        self.commands_rejected = 0
        self.days_without_command = 0

    # --- commands ----------------------------------------------------------------------------------------

    def check_command(self, command: Command) -> tuple[str | None, bool]:
        """(why ``command`` is refused, or None; whether it is only a question of timing: a past or future day,
        another episode, a season that ended)."""
        day, mm = command.day, command.mm
        if command.field not in ("", self.field):
            return f"frame_id {command.field!r} is not this simulator's field {self.field!r}", False
        if command.episode not in (ANY_EPISODE, self.episode):
            return f"episode {command.episode} is not the current episode {self.episode}", True
        if self.ended:
            return self._ended_text(), True
        if day < self.day:
            return f"day {day} is past: the current day is {self.day}", True
        if day > self.day:
            return f"day {day} is in the future: the current day is {self.day}", True
        today_ns = farm_time_ns(self.sowing, day)
        if command.stamp_ns not in (0, today_ns):  # the client's farm time is another season's, or wrong
            sec, ns = divmod(command.stamp_ns, 10**9)
            return (f"header.stamp {sec}.{ns:09d} s is not the farm time of day {day} "
                    f"({today_ns // 10**9} s: {self.sowing + timedelta(days=day)} 00:00 UTC)"), False
        if not math.isfinite(mm):
            return f"irrigation {mm!r} mm is not a finite number", False
        if mm < 0.0:
            return f"irrigation {mm!r} mm is negative", False
        if mm > self.max_mm:
            return f"irrigation {mm!r} mm exceeds the limit of {self.max_mm:g} mm/day", False
        return None, False

    def command(self, command: Command, and_step: bool = False, lockstep: bool = True) -> CommandOutcome:
        """Check a command; an accepted one becomes today's pending command (replacing an earlier one).
        ``and_step``: the client also asks for the step (refused unless ``lockstep``)."""
        self.commands_received += 1
        sequence = self.commands_received
        problem, timing = self.check_command(command)
        if problem is None and and_step and not lockstep:
            problem, timing = FREE_RUNNING_STEP_REFUSAL, False
        if problem is None:
            self.commands_accepted += 1
            self.pending = (command, sequence)
            text = (f"accepted {command.mm:g} mm for day {self.day} (episode {self.episode})"
                    + (", stepping" if and_step else ""))
        else:
            self.commands_rejected += 1
            text = f"rejected: {problem}"
        return CommandOutcome(problem is None, text, timing, command, sequence, self.day)

    # --- step --------------------------------------------------------------------------------------------

    def step(self) -> StepOutcome:
        """Advance one day with today's pending command (none: 0 mm); the pending command is used up either
        way."""
        if self.ended:
            return StepOutcome(self._ended_text(), self.episode, self.day)
        day, obs_before = self.day, self.obs
        mm, sequence, command = 0.0, -1, None
        if self.pending is not None and self.pending[0].day == day:
            command, sequence = self.pending
            mm = float(command.mm)
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
                           truncated, info["yield_t_ha"] if terminated else 0.0, sequence, command)

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
