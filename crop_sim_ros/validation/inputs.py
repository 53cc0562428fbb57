"""Reader of the SIMPLE v1.1 reference input set (the R distribution's ``Input``, ``Observation`` and
``Weather`` folders). Every problem is an :class:`InputError` naming the file and line.

Decisions on the set's irregularities (each checked against the files):

- ``Simulation Management.csv`` lists some treatments twice, once switched on (``ON_Off`` 1) and once
  off (0): a treatment runs if any of its rows switches it on. Its water-stress switch (``Water`` yes/no)
  comes from the switching-on rows (from all its rows when ``--all`` runs a treatment that no row switches
  on); rows that disagree are an error. A treatment without a row there has water stress on.
- ``Irrigation.csv`` rows are read as the reference implementation reads them (``irrigation_rows=
  "reference"``, the default): a row irrigates the treatments whose species and experiment are the row's
  (crop names through :func:`canonical_crop` on both sides, which changes no match in this set). Two groups
  of rows match nothing and are dropped: ``wheat1,UFGA7801,1,78235,13`` (no wheat experiment UFGA7801) and
  the 18 ``soybean,OHWO8801,1`` rows (595 mm; OHWO8801 is experiment OHWO's weather file, not an
  experiment). ``irrigation_rows="attributed"`` is our reading of the same rows: a row whose crop has no
  experiment of that name but whose experiment belongs to exactly one crop is that crop's ("wheat1" sits
  among the soybean UFGA7801 rows), and a row whose experiment is the weather file of exactly one
  experiment of its crop belongs to that experiment. It gives soybean UFGA7801/1 13 mm more (final
  biomass +5.8 %, maturity 2 days later) and soybean OHWO/1 595 mm (PAW up to 320 mm higher, growth
  unchanged).
- Several ``Irrigation.csv`` rows on one day add up (DSSAT's convention: each row is an application;
  the HSCE0701 wheat treatments have two applications on many days). This includes the few rows that
  repeat a day with the same amount (soybean UFGA8401 before sowing, tomato UFBR9401 day 94113).
- Irrigation before the sowing day is not applied: the season starts at sowing with a full root zone.
- Weather file names in ``Treatment.csv`` lack the extension, and the case of the files varies
  (``AUCB7001.wth``): the file is found by name, case-insensitively.
"""

from __future__ import annotations

import csv
import re
from collections import defaultdict
from dataclasses import dataclass
from datetime import date
from pathlib import Path

from ..model.parameters import canonical_crop
from ..weather.readers import dssat_date
from ..weather.series import WeatherError

TREATMENT_FILE = Path("Input") / "Treatment.csv"
MANAGEMENT_FILE = Path("Input") / "Simulation Management.csv"
IRRIGATION_FILE = Path("Input") / "Irrigation.csv"
OBSERVATION_DIR = Path("Observation")
# How Irrigation.csv rows find their treatment (see the module docstring); the first is the default.
IRRIGATION_ROWS = ("reference", "attributed")
WEATHER_DIR = Path("Weather")


class InputError(ValueError):
    """A missing or malformed file of the reference input set; the message names file and line."""


@dataclass(frozen=True)
class Treatment:
    """One row of ``Treatment.csv`` with its switches from ``Simulation Management.csv``.

    ``crop`` is the canonical crop name (:func:`canonical_crop`); dates are calendar dates (the file's
    YYDDD); ``harvest`` is None where the crop is harvested at maturity; ``co2_ppm`` in ppm;
    ``initial_biomass_kg_ha`` kg ha-1; ``initial_thermal_time_degc_d`` degC d; ``fsolar_max`` and
    ``initial_fsolar`` fractions; ``line`` is the row's line in ``Treatment.csv``.
    """

    crop: str
    experiment: str
    number: int
    label: str
    weather: str
    co2_ppm: float
    sowing: date
    harvest: date | None
    soil: str
    cultivar: str
    irrigation_treatment: int
    fsolar_max: float
    initial_biomass_kg_ha: float
    initial_thermal_time_degc_d: float
    initial_fsolar: float
    switched_on: bool
    water_stress: bool
    line: int

    @property
    def key(self) -> tuple[str, str, int]:
        """(crop, experiment, treatment number): how observations and management rows find it."""
        return (self.crop, self.experiment, self.number)

    @property
    def name(self) -> str:
        return f"{self.crop}/{self.experiment}/{self.number}"


@dataclass(frozen=True)
class Observation:
    """One observed value: ``variable`` is biomass_kg_ha, yield_kg_ha (kg ha-1) or fsolar (fraction);
    ``observed_on`` is the file's Date (None where the file has no Date column)."""

    crop: str
    experiment: str
    treatment: int
    days_after_planting: int
    variable: str
    value: float
    observed_on: date | None
    source: str


# Observation file columns -> our variable names.
OBSERVED_VARIABLES = {"Biomass": "biomass_kg_ha", "Yield": "yield_kg_ha", "FSolar": "fsolar"}


def _rows(path: Path) -> list[tuple[int, dict[str, str]]]:
    """(line number, row) of a CSV file; header cells keyed by their letters, digits and '_' only
    ('Species*' -> 'Species', 'InitialTT ' -> 'InitialTT')."""
    if not path.is_file():
        raise InputError(f"input file not found: {path}")
    with path.open(newline="", encoding="utf-8", errors="replace") as handle:
        reader = csv.reader(handle)
        header = [re.sub(r"[^A-Za-z0-9_]", "", cell) for cell in next(reader, [])]
        rows = [(number, dict(zip(header, (cell.strip() for cell in cells))))
                for number, cells in enumerate(reader, start=2) if any(cell.strip() for cell in cells)]
    return rows


def _field(row: dict[str, str], column: str, path: Path, line: int, convert=str, required: bool = True):
    text = row.get(column)
    if text is None:
        raise InputError(f"{path}, line {line}: no column {column!r}")
    if not text:
        if required:
            raise InputError(f"{path}, line {line}, column {column}: empty")
        return None
    try:
        if convert is date:
            return dssat_date(text, f"{path}, line {line}, column {column}")
        return convert(float(text)) if convert is int else convert(text)
    except WeatherError as error:
        raise InputError(str(error)) from None
    except ValueError:
        raise InputError(f"{path}, line {line}, column {column}: {text!r} is not a "
                         f"{'number' if convert in (int, float) else convert.__name__}") from None


def _yes_no(text: str, path: Path, line: int) -> bool:
    if text.lower() not in ("yes", "no"):
        raise InputError(f"{path}, line {line}, column Water: expected yes or no, got {text!r}")
    return text.lower() == "yes"


def read_treatments(inputs_dir: str | Path) -> list[Treatment]:
    """Every treatment of ``Treatment.csv``, with its switches from ``Simulation Management.csv``."""
    base = Path(inputs_dir)
    path = base / MANAGEMENT_FILE
    switches: dict[tuple, list[tuple[bool, bool, int]]] = defaultdict(list)
    for line, row in _rows(path):
        key = (canonical_crop(_field(row, "Species", path, line)), _field(row, "Exp", path, line),
               _field(row, "Trt", path, line, int))
        on = _field(row, "ON_Off", path, line, int)
        switches[key].append((on == 1, _yes_no(_field(row, "Water", path, line), path, line), line))

    path = base / TREATMENT_FILE
    treatments = []
    for line, row in _rows(path):
        crop = canonical_crop(_field(row, "Species", path, line))
        experiment = _field(row, "Exp", path, line)
        number = _field(row, "Trt", path, line, int)
        rows = switches.get((crop, experiment, number), [])
        switched_on = any(on for on, _, _ in rows)
        deciding = [(water, at) for on, water, at in rows if on or not switched_on]
        if len({water for water, _ in deciding}) > 1:
            raise InputError(f"{base / MANAGEMENT_FILE}, lines {', '.join(str(at) for _, at in deciding)}: "
                             f"the Water switch of {crop}/{experiment}/{number} disagrees")
        treatments.append(Treatment(
            crop=crop, experiment=experiment, number=number, label=row.get("Label", ""),
            weather=_field(row, "weather", path, line), co2_ppm=_field(row, "CO2", path, line, float),
            sowing=_field(row, "SowingDate", path, line, date),
            harvest=_field(row, "HarvestDate", path, line, date, required=False),
            soil=_field(row, "SoilName", path, line), cultivar=_field(row, "Cultivar", path, line),
            irrigation_treatment=_field(row, "IrrigationTrt", path, line, int),
            fsolar_max=_field(row, "MaxIntercept", path, line, float),
            initial_biomass_kg_ha=_field(row, "InitialBio", path, line, float),
            initial_thermal_time_degc_d=_field(row, "InitialTT", path, line, float),
            initial_fsolar=_field(row, "InitialFsolar", path, line, float),
            switched_on=switched_on, water_stress=deciding[0][0] if deciding else True, line=line))
    return treatments


def read_irrigation(inputs_dir: str | Path, treatments: list[Treatment],
                    irrigation_rows: str = "reference") -> dict[tuple[str, str, int], dict[date, float]]:
    """Irrigation, mm per day, keyed by (crop, experiment, irrigation treatment) of ``treatments``.
    ``irrigation_rows`` (one of :data:`IRRIGATION_ROWS`, see the module docstring) says how a row finds
    its treatment; rows that match no treatment's experiment are left out."""
    if irrigation_rows not in IRRIGATION_ROWS:
        raise InputError(f"irrigation_rows must be one of {', '.join(IRRIGATION_ROWS)}, got {irrigation_rows!r}")
    attributed = irrigation_rows == "attributed"
    path = Path(inputs_dir) / IRRIGATION_FILE
    experiments = {(t.crop, t.experiment) for t in treatments}
    crops_of_experiment = defaultdict(set)
    experiments_of_weather = defaultdict(set)
    for t in treatments:
        crops_of_experiment[t.experiment].add(t.crop)
        experiments_of_weather[(t.crop, t.weather.upper())].add(t.experiment)
    events: dict[tuple[str, str, int], dict[date, float]] = defaultdict(lambda: defaultdict(float))
    for line, row in _rows(path):
        crop = canonical_crop(_field(row, "Species", path, line))
        experiment = _field(row, "Exp", path, line)
        if attributed and (crop, experiment) not in experiments and len(crops_of_experiment[experiment]) == 1:
            crop = next(iter(crops_of_experiment[experiment]))
        if (attributed and (crop, experiment) not in experiments
                and len(experiments_of_weather[(crop, experiment.upper())]) == 1):
            experiment = next(iter(experiments_of_weather[(crop, experiment.upper())]))
        if (crop, experiment) not in experiments:
            continue
        amount_mm = _field(row, "IrrAmount", path, line, float)
        if amount_mm < 0:
            raise InputError(f"{path}, line {line}, column IrrAmount: negative irrigation {amount_mm} mm")
        events[(crop, experiment, _field(row, "Trt", path, line, int))][
            _field(row, "IrrDate", path, line, date)] += amount_mm
    return {key: dict(days) for key, days in events.items()}


def weather_file(inputs_dir: str | Path, name: str) -> Path:
    """``Weather/<name>.WTH`` of the input set, the extension's and the name's case ignored."""
    folder = Path(inputs_dir) / WEATHER_DIR
    if not folder.is_dir():
        raise InputError(f"weather folder not found: {folder}")
    wanted = f"{name}.wth".lower()
    matches = [p for p in folder.iterdir() if p.name.lower() == wanted]
    if not matches:
        raise InputError(f"weather file {name}.WTH (named in {TREATMENT_FILE}) not found in {folder}")
    return matches[0]


def read_observations(inputs_dir: str | Path) -> list[Observation]:
    """Every non-empty biomass, yield and fSolar value of ``Observation/Obs_<crop>_<experiment>.csv``."""
    folder = Path(inputs_dir) / OBSERVATION_DIR
    if not folder.is_dir():
        raise InputError(f"observation folder not found: {folder}")
    observations = []
    for path in sorted(folder.glob("Obs_*.csv")):
        match = re.fullmatch(r"Obs_([^_]+)_(.+)\.csv", path.name)
        if not match:
            raise InputError(f"{path}: expected a name Obs_<crop>_<experiment>.csv")
        crop, experiment = canonical_crop(match[1]), match[2]
        for line, row in _rows(path):
            treatment = _field(row, "Trt", path, line, int)
            dap = _field(row, "DAP", path, line, int)
            observed_on = _field(row, "Date", path, line, date, required=False) if "Date" in row else None
            for column, variable in OBSERVED_VARIABLES.items():
                if column in row:
                    value = _field(row, column, path, line, float, required=False)
                    if value is not None:
                        observations.append(Observation(crop, experiment, treatment, dap, variable, value,
                                                        observed_on, f"{path}, line {line}"))
    return observations
