"""PPO policies of Stable-Baselines3: the fixed observation features and action mapping the network sees
(shared by training and the policy file loader), and :class:`SB3Policy`, which loads a policy file.

Observation features (:func:`features`, fixed, no running statistics): every observation value scaled to
about unit range (rain as log1p), plus three derived values the rule-maker would also compute from the
same observation: the water level at which transpiration meets today's demand, ``ET0/0.096`` (0.096 is
ARID's daily uptake coefficient) with ET0 estimated by FAO-56 Penman-Monteith from today's exact weather
(:func:`estimated_et0_mm`), the margin ``PAW + rain today - that level``, and tomorrow's margin from the
noisy forecast.

Action mapping (:func:`action_to_mm`), ``mode``:

- ``mm``: a in [-1, 1] -> irrigation (a + 1) / 2 * 100 mm;
- ``target``: a in [-1, 1] -> a water level L in [TARGET_LOW_MM, TARGET_HIGH_MM], and the policy irrigates
  ``clip(L - PAW - rain today, 0, 100)`` mm: the network chooses, day by day, the level to refill to;
- ``margin``: as ``target`` with L = ET0 / 0.096 + m, m = MARGIN_CENTER_MM + MARGIN_SPAN_MM * a: the
  network chooses the safety margin above today's estimated no-stress level. With a = 0 this is a fixed
  "demand + 4 mm" rule (``DemandMarginPolicy`` in :mod:`crop_agent_ros.policies.rules`); PPO learns a
  state-dependent correction of it. Most of the skill of the shipped policy comes from this design (the
  ET0 estimate and the no-stress level are agronomy, not learning): evaluate ``margin4`` beside ``ppo``.
- ``demand``: L = (1 + DEMAND_SPAN * a) * ET0 / 0.096 + m0 (m0 = ``margin_center_mm``): the network scales
  the no-stress level. a = 0 is again the ``margin4`` rule, but with the default span of 1 the action
  reaches "no irrigation" (a = -1: L = m0, below any useful PAW), e.g. late in the season when the canopy
  has senesced; the ``margin`` mode cannot (its lowest level is ET0/0.096 - 11 mm).

Feature sets: ``full`` (the 23 features above), ``compact`` (9 of them) and ``phenology`` (``full`` plus
two phenology features: thermal time as a fraction of the cultivar's Tsum, and the progress of canopy
senescence, (TT - (Tsum - I50B)) / I50B clipped to [-1, 1.5], with Russet Burbank's Tsum = 2300 and
I50B = 400 degC d).

Either way the policy is a function of the observation alone and returns mm in [0, 100].

A policy file is checked when it loads (:class:`SB3Policy`): a file that is not a Stable-Baselines3 PPO zip,
a config with an unknown action mode or feature set, or a network whose observation space is not the
feature vector of its feature set (23 values for ``full``) or whose action space is not one value raises
:class:`PolicyFileError`, before any action is asked of it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from crop_sim_ros.model.simple import WATER_UPTAKE_COEFFICIENT  # ARID's water uptake coefficient, d-1

from .base import (ACTION_HIGH_MM, DAYS_SINCE_SOWING, FORECAST_RAIN_MM, PAW_MM, TODAY_RAIN_MM, BasePolicy)

TARGET_LOW_MM = 20.0
TARGET_HIGH_MM = 140.0
# margin mode: m = MARGIN_CENTER_MM + MARGIN_SPAN_MM * a. The centre is the best fixed margin on generated
# training seasons (benton-generated 0..199, noise seed 0: margins 3-6 mm within 0.0002 t/ha of each other;
# see the tuning notes in the module docstring); a = 0 (an untrained network) is that fixed-margin rule.
MARGIN_CENTER_MM = 4.0
MARGIN_SPAN_MM = 15.0
ACTION_MODES = ("mm", "target", "margin", "demand")
DEMAND_SPAN = 1.0
FEATURE_VERSION = 2
# Benton County, WA (the scenarios' site: AgWeatherNet Benton E. and Paterson), and the day of year of an
# early-April sowing: used only to estimate ET0 from the observation.
SITE_LATITUDE_DEG = 46.2
SITE_ELEVATION_M = 200.0
SOWING_DAY_OF_YEAR = 95
N_FEATURES = 23
# Russet Burbank (SIMPLE Table 1a), for the phenology features only
CULTIVAR_TSUM_DEGC_D = 2300.0
CULTIVAR_I50B_DEGC_D = 400.0

HERE = Path(__file__).resolve().parent
SHIPPED_PPO = HERE / "ppo_benton.zip"

# fixed centre and scale of each observation value (see the observation table of IRRIGATION_TASK.md)
_CENTER = np.array([8, 1200, 90, 22, 8, 15, 0, 18, 369, 10, 2.5, 22, 8, 15, 0, 18, 369, 10, 2.5, 80], float)
_SCALE = np.array([8, 1200, 90, 12, 8, 9, 1, 9, 30, 5, 2, 12, 8, 9, 1, 9, 30, 5, 2, 40], float)


def estimated_et0_mm(obs: np.ndarray, tomorrow: bool = False) -> np.ndarray:
    """FAO-56 Penman-Monteith ET0 (mm/day) from the observation's weather (today's exact values, or
    tomorrow's noisy forecast), at the Benton County site (SITE_LATITUDE_DEG, SITE_ELEVATION_M) with the
    day of year estimated as SOWING_DAY_OF_YEAR + days since sowing (the observation has no date)."""
    from crop_sim_ros.model.et0 import penman_monteith
    c = 11 if tomorrow else 3
    tmax, tmin = obs[:, c], np.minimum(obs[:, c + 1], obs[:, c])
    doy = np.clip(SOWING_DAY_OF_YEAR + obs[:, DAYS_SINCE_SOWING] + (1 if tomorrow else 0), 1, 365)
    return penman_monteith(tmax, tmin, np.maximum(obs[:, c + 4], 0.01), np.maximum(obs[:, c + 6], 0.01),
                           np.maximum(obs[:, c + 7], 0.0), doy, SITE_LATITUDE_DEG, SITE_ELEVATION_M)


def _demand_level_mm(obs: np.ndarray, tomorrow: bool = False) -> np.ndarray:
    """ET0 / 0.096: the PAW (after the day's water) at which transpiration meets the day's demand."""
    return estimated_et0_mm(obs, tomorrow) / WATER_UPTAKE_COEFFICIENT


# the "compact" feature set: biomass, TT, days, today's rain, forecast rain, PAW, and the three derived values
COMPACT = (0, 1, 2, 6, 14, 19, 20, 21, 22)
FEATURE_SETS = {"full": N_FEATURES, "compact": len(COMPACT), "phenology": N_FEATURES + 2}


def features(obs: np.ndarray, feature_set: str = "full") -> np.ndarray:
    """(N, 20) observations -> (N, 23) float32 features (see the module docstring); ``feature_set="compact"``
    keeps only the 9 columns of COMPACT (the network then cannot react to the noisy forecast details)."""
    full = _full_features(obs)
    if feature_set == "full":
        return full
    if feature_set == "compact":
        return np.ascontiguousarray(full[:, COMPACT])
    if feature_set == "phenology":
        tt = np.atleast_2d(np.asarray(obs, dtype=float))[:, 1]
        fraction = tt / CULTIVAR_TSUM_DEGC_D
        senescence = np.clip((tt - (CULTIVAR_TSUM_DEGC_D - CULTIVAR_I50B_DEGC_D)) / CULTIVAR_I50B_DEGC_D, -1.0, 1.5)
        return np.concatenate([full, np.stack([fraction, senescence], axis=1).astype(np.float32)], axis=1)
    raise ValueError(f"unknown feature set {feature_set!r}; known: {', '.join(FEATURE_SETS)}")


def _full_features(obs: np.ndarray) -> np.ndarray:
    obs = np.atleast_2d(np.asarray(obs, dtype=float))
    x = (obs - _CENTER) / _SCALE
    x[:, TODAY_RAIN_MM] = np.log1p(np.maximum(obs[:, TODAY_RAIN_MM], 0.0)) - 1.0
    x[:, FORECAST_RAIN_MM] = np.log1p(np.maximum(obs[:, FORECAST_RAIN_MM], 0.0)) - 1.0
    level_today = _demand_level_mm(obs)
    level_tomorrow = _demand_level_mm(obs, tomorrow=True)
    margin = obs[:, PAW_MM] + obs[:, TODAY_RAIN_MM] - level_today
    derived = np.stack([(level_today - 60.0) / 30.0, margin / 30.0,
                        (obs[:, PAW_MM] + obs[:, FORECAST_RAIN_MM] - level_tomorrow) / 30.0], axis=1)
    return np.clip(np.concatenate([x, derived], axis=1), -10.0, 10.0).astype(np.float32)


def action_to_mm(action: np.ndarray, obs: np.ndarray, mode: str, margin_center_mm: float = MARGIN_CENTER_MM,
                 margin_span_mm: float = MARGIN_SPAN_MM, demand_span: float = DEMAND_SPAN) -> np.ndarray:
    """Network action(s) in [-1, 1] -> irrigation mm in [0, 100] (see the module docstring)."""
    a = np.clip(np.asarray(action, dtype=float).reshape(-1), -1.0, 1.0)
    obs = np.atleast_2d(np.asarray(obs, dtype=float))
    if mode == "mm":
        return (a + 1.0) * 0.5 * ACTION_HIGH_MM
    if mode == "target":
        level = TARGET_LOW_MM + (a + 1.0) * 0.5 * (TARGET_HIGH_MM - TARGET_LOW_MM)
        return np.clip(level - obs[:, PAW_MM] - obs[:, TODAY_RAIN_MM], 0.0, ACTION_HIGH_MM)
    if mode == "margin":
        margin = margin_center_mm + margin_span_mm * a
        level = _demand_level_mm(obs) + margin
        return np.clip(level - obs[:, PAW_MM] - obs[:, TODAY_RAIN_MM], 0.0, ACTION_HIGH_MM)
    if mode == "demand":
        level = (1.0 + demand_span * a) * _demand_level_mm(obs) + margin_center_mm
        return np.clip(level - obs[:, PAW_MM] - obs[:, TODAY_RAIN_MM], 0.0, ACTION_HIGH_MM)
    raise ValueError(f"unknown action mode {mode!r}; known: {', '.join(ACTION_MODES)}")


class PolicyFileError(ValueError):
    """A policy file that cannot be this task's policy (the message names the file and why)."""


def config_path_for(model_path: Path) -> Path:
    return Path(model_path).with_suffix(".json")


class SB3Policy(BasePolicy):
    """A PPO policy file (``.zip``) with its ``.json`` config beside it; deterministic actions."""

    def __init__(self, path: str | Path = SHIPPED_PPO, name: str = "ppo", device: str = "cpu"):
        from stable_baselines3 import PPO
        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"policy file {self.path} does not exist (train one with `crop-sim train`)")
        cfg_file = config_path_for(self.path)
        try:
            self.config = json.loads(cfg_file.read_text()) if cfg_file.exists() else {}
            self.action_mode = self.config.get("action_mode", "mm")
            self.feature_set = self.config.get("feature_set", "full")
            self.mapping = {k: float(v) for k, v in self.config.get("action_mapping", {}).items()}
        except (ValueError, TypeError, AttributeError) as error:
            raise PolicyFileError(f"policy config {cfg_file}: {error}") from None
        if self.action_mode not in ACTION_MODES or self.feature_set not in FEATURE_SETS:
            raise PolicyFileError(f"policy config {cfg_file}: action_mode {self.action_mode!r} / feature_set "
                                  f"{self.feature_set!r} not among {ACTION_MODES} / {tuple(FEATURE_SETS)}")
        try:
            self.model = PPO.load(str(self.path), device=device)
        except Exception as error:  # noqa: BLE001 - a foreign file fails anywhere in zip, pickle or torch
            raise PolicyFileError(f"policy file {self.path} is not a Stable-Baselines3 PPO policy: "
                                  f"{type(error).__name__}: {error}") from None
        self._check_spaces()
        self.name = name

    def _check_spaces(self) -> None:
        """The network must take this feature set's vector and give one action: refuse it at load, not at the
        first action (where SB3 fails with "Unexpected observation shape" in the middle of a season)."""
        from gymnasium import spaces
        observation, action = self.model.observation_space, self.model.action_space
        features_expected = (FEATURE_SETS[self.feature_set],)
        if not isinstance(observation, spaces.Box) or observation.shape != features_expected:
            raise PolicyFileError(
                f"policy file {self.path}: its network observes {_describe(observation)}, but the task's "
                f"{self.feature_set!r} features are {features_expected[0]} values (train it with `crop-sim train`)")
        if not isinstance(action, spaces.Box) or action.shape != (1,):
            raise PolicyFileError(f"policy file {self.path}: its network acts with {_describe(action)}, but the task's "
                                  "action is one value (the irrigation of the day)")

    def _act_batch(self, obs):
        action, _ = self.model.predict(features(obs, self.feature_set), deterministic=True)
        return action_to_mm(action, obs, self.action_mode, **self.mapping)

    def describe(self):
        return {"name": self.name, "path": str(self.path), "action_mode": self.action_mode,
                "feature_set": self.feature_set}


def _describe(space) -> str:
    shape = getattr(space, "shape", None)
    return f"{type(space).__name__} of shape {shape}" if shape is not None else type(space).__name__
