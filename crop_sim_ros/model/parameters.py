"""SIMPLE parameters: species, cultivar, soil and management, with units, and the crop library.

Two parameter sources:

- ``zhao2019`` (canonical, embedded): Zhao et al. (2019) Table 1a (14 crops, 22 cultivars) and
  Table 1b (the soils of the validation sites).
- ``simple_r``: the tables shipped with the SIMPLE v1.1 R distribution (``Input/Species parameter.csv``,
  ``Input/Cultivar.csv``, ``Input/Soil.csv``), read from a directory at run time. Some values differ from
  the paper (e.g. Russet Burbank Tsum 2200 vs 2300).

Species parameters
------------------
=============================== ======== ============ =================================================
Name                            Symbol   Unit         Description
=============================== ======== ============ =================================================
base_temperature_degc           Tbase    degC         below it no thermal time accrues, no growth
optimal_temperature_degc        Topt     degC         at and above it temperature does not limit growth
radiation_use_efficiency        RUE      g MJ-1       above-ground biomass per MJ of intercepted radiation
i50_max_heat_degc_d             I50maxH  degC d       largest daily shortening of the canopy's life by heat
i50_max_water_degc_d            I50maxW  degC d       largest daily shortening of the canopy's life by drought
heat_stress_onset_degc          Theat    degC         TMAX above which heat reduces growth
extreme_heat_degc               Textreme degC         TMAX above which growth stops
co2_sensitivity_per_100ppm      S_CO2    (100 ppm)-1  relative RUE gain per 100 ppm of CO2 above 350 ppm
water_stress_sensitivity        S_water  1            f_water = 1 - S_water * ARID
=============================== ======== ============ =================================================

Cultivar parameters
-------------------
=============================== ======== ============ =================================================
Name                            Symbol   Unit         Description
=============================== ======== ============ =================================================
thermal_time_to_maturity_degc_d Tsum     degC d       thermal time from sowing to maturity
harvest_index                   HI       1            yield / above-ground biomass at maturity
i50a_degc_d                     I50A     degC d       thermal time to reach half of fSolar_max (growth)
i50b_degc_d                     I50B     degC d       thermal time before maturity at which fSolar falls
                                                      to half of fSolar_max (senescence)
=============================== ======== ============ =================================================

Soil parameters
---------------
=============================== ======== ============ =================================================
Name                            Symbol   Unit         Description
=============================== ======== ============ =================================================
available_water_capacity        AWC      mm mm-1      plant-available water per mm of root zone
runoff_curve_number             RCN      1            SCS curve number (0-100]
deep_drainage_coefficient       DDC      d-1          fraction of water above capacity drained per day
root_zone_depth_mm              RZD      mm           depth of the one-bucket root zone
=============================== ======== ============ =================================================
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping


class UnknownNameError(KeyError):
    """An unknown crop, cultivar or soil name; the message lists the names that exist."""

    def __str__(self) -> str:  # KeyError quotes its message; show it plainly
        return str(self.args[0])


@dataclass(frozen=True)
class Species:
    """Species parameters of SIMPLE (Zhao 2019 Table 1a, left part). See the module table for units."""

    name: str
    base_temperature_degc: float
    optimal_temperature_degc: float
    radiation_use_efficiency: float
    i50_max_heat_degc_d: float
    i50_max_water_degc_d: float
    heat_stress_onset_degc: float
    extreme_heat_degc: float
    co2_sensitivity_per_100ppm: float
    water_stress_sensitivity: float

    def __post_init__(self) -> None:
        _require(self.optimal_temperature_degc > self.base_temperature_degc,
                 f"species {self.name}: Topt must exceed Tbase")
        _require(self.extreme_heat_degc > self.heat_stress_onset_degc,
                 f"species {self.name}: Textreme must exceed Theat")
        _require(self.radiation_use_efficiency > 0, f"species {self.name}: RUE must be positive")


@dataclass(frozen=True)
class Cultivar:
    """Cultivar parameters of SIMPLE (Zhao 2019 Table 1a, right part). See the module table for units."""

    species: str
    name: str
    thermal_time_to_maturity_degc_d: float
    harvest_index: float
    i50a_degc_d: float
    i50b_degc_d: float

    def __post_init__(self) -> None:
        _require(self.thermal_time_to_maturity_degc_d > 0, f"cultivar {self.name}: Tsum must be positive")
        _require(0 < self.harvest_index <= 1, f"cultivar {self.name}: HI must be in (0, 1]")


@dataclass(frozen=True)
class Soil:
    """One-bucket soil of SIMPLE (Zhao 2019 Table 1b). See the module table for units."""

    name: str
    available_water_capacity: float
    runoff_curve_number: float
    deep_drainage_coefficient: float
    root_zone_depth_mm: float

    def __post_init__(self) -> None:
        _require(0 < self.available_water_capacity < 1, f"soil {self.name}: AWC must be in (0, 1)")
        _require(0 < self.runoff_curve_number <= 100, f"soil {self.name}: RCN must be in (0, 100]")
        _require(0 <= self.deep_drainage_coefficient <= 1, f"soil {self.name}: DDC must be in [0, 1]")
        _require(self.root_zone_depth_mm > 0, f"soil {self.name}: RZD must be positive")

    @property
    def capacity_mm(self) -> float:
        """Plant-available water of a full root zone, mm (AWC * RZD)."""
        return self.available_water_capacity * self.root_zone_depth_mm


@dataclass(frozen=True)
class Management:
    """Management of one field.

    ============================= ========= ======================================================
    Name                          Unit      Description
    ============================= ========= ======================================================
    co2_ppm                       ppm       atmospheric CO2 concentration
    fsolar_max                    1         largest fraction of radiation the canopy intercepts
    initial_biomass_kg_ha         kg ha-1   above-ground biomass on the sowing day
    initial_thermal_time_degc_d   degC d    thermal time on the sowing day
    initial_fsolar                1         radiation interception on the sowing day
    water_stress                  bool      False switches water stress off (f_water = 1)
    harvest_day                   d         harvest this many days after sowing (None: at maturity)
    initial_paw_mm                mm        plant-available water on the sowing day (None: full)
    ============================= ========= ======================================================
    """

    co2_ppm: float = 350.0
    fsolar_max: float = 0.95
    initial_biomass_kg_ha: float = 1.0
    initial_thermal_time_degc_d: float = 0.0
    initial_fsolar: float = 0.001
    water_stress: bool = True
    harvest_day: int | None = None
    initial_paw_mm: float | None = None

    def __post_init__(self) -> None:
        _require(self.co2_ppm >= 0, "management: co2_ppm must be >= 0")
        _require(0 < self.fsolar_max <= 1, "management: fsolar_max must be in (0, 1]")
        _require(self.initial_biomass_kg_ha >= 0, "management: initial_biomass_kg_ha must be >= 0")
        _require(0 <= self.initial_fsolar <= 1, "management: initial_fsolar must be in [0, 1]")
        _require(self.harvest_day is None or self.harvest_day >= 0, "management: harvest_day must be >= 0")
        _require(self.initial_paw_mm is None or self.initial_paw_mm >= 0,
                 "management: initial_paw_mm must be >= 0")


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


def normalize_name(name: str) -> str:
    """Lower case, letters and digits only: 'Dry bean' -> 'drybean', 'Russet Burbank' -> 'russetburbank'."""
    return re.sub(r"[^a-z0-9?]", "", name.lower())


# Other spellings of crop names found in the SIMPLE input files.
_CROP_ALIASES = {"grbean": "greenbean", "wheat1": "wheat"}


def canonical_crop(name: str) -> str:
    key = normalize_name(name)
    return _CROP_ALIASES.get(key, key)


@dataclass(frozen=True)
class CropLibrary:
    """Species, cultivars and soils of one parameter source, looked up by name (case and spaces ignored)."""

    source: str
    species_by_crop: Mapping[str, Species]
    cultivars_by_crop: Mapping[str, Mapping[str, Cultivar]]
    soils: Mapping[str, Soil] = field(default_factory=dict)

    def crops(self) -> list[str]:
        return sorted(self.species_by_crop)

    def species(self, crop: str) -> Species:
        key = canonical_crop(crop)
        if key not in self.species_by_crop:
            raise UnknownNameError(f"unknown crop {crop!r} in parameter source {self.source!r}; "
                                   f"known crops: {', '.join(self.crops())}")
        return self.species_by_crop[key]

    def cultivars(self, crop: str) -> list[str]:
        self.species(crop)
        return [c.name for c in self.cultivars_by_crop[canonical_crop(crop)].values()]

    def cultivar(self, crop: str, cultivar: str) -> Cultivar:
        self.species(crop)
        table = self.cultivars_by_crop[canonical_crop(crop)]
        key = normalize_name(cultivar)
        if key in table:
            return table[key]
        # Names that lost a character to a file's encoding ('Prata An?') match by pattern.
        if "?" in key:
            pattern = re.compile(re.escape(key).replace(r"\?", ".?") + "$")
            matches = [c for k, c in table.items() if pattern.match(k)]
            if len(matches) == 1:
                return matches[0]
        raise UnknownNameError(f"unknown cultivar {cultivar!r} of crop {crop!r} in parameter source "
                               f"{self.source!r}; known cultivars: {', '.join(self.cultivars(crop))}")

    def soil(self, name: str) -> Soil:
        key = normalize_name(name)
        if key not in self.soils:
            raise UnknownNameError(f"unknown soil {name!r} in parameter source {self.source!r}; "
                                   f"known soils: {', '.join(s.name for s in self.soils.values())}")
        return self.soils[key]


# --- Zhao et al. (2019) Table 1a -------------------------------------------------------------------
# Species: Tbase, Topt, RUE, I50maxH, I50maxW, Theat, Textreme, S_CO2, S_water
_ZHAO_SPECIES = {
    "Wheat": (0, 15, 1.24, 100, 25, 34, 45, 0.08, 0.4),
    "Rice": (9, 26, 1.24, 100, 10, 34, 50, 0.08, 1.0),
    "Maize": (8, 28, 2.10, 100, 12, 34, 50, 0.01, 1.2),
    "Soybean": (6, 27, 0.86, 120, 20, 36, 50, 0.07, 0.9),
    "Dry bean": (5, 27, 0.80, 90, 20, 32, 45, 0.07, 0.9),
    "Peanut": (10, 28, 1.20, 100, 5, 36, 50, 0.07, 2.0),
    "Potato": (4, 22, 1.30, 50, 30, 34, 45, 0.10, 0.4),
    "Cassava": (12, 28, 1.10, 100, 15, 38, 50, 0.07, 1.0),
    "Tomato": (6, 26, 1.00, 100, 5, 32, 45, 0.07, 2.5),
    "Sweetcorn": (8, 27, 1.70, 100, 5, 34, 50, 0.01, 2.0),
    "Greenbean": (5, 27, 0.86, 100, 10, 32, 45, 0.07, 0.4),
    "Carrot": (4, 22, 1.00, 100, 5, 32, 45, 0.07, 2.0),
    "Cotton": (11, 28, 0.85, 40, 10, 35, 50, 0.09, 1.2),
    "Banana": (10, 25, 0.80, 100, 5, 34, 45, 0.07, 2.5),
}
# Cultivars: crop, name, Tsum, HI, I50A, I50B
_ZHAO_CULTIVARS = [
    ("Wheat", "Yecora Rojo", 2200, 0.36, 480, 200),
    ("Wheat", "Batten", 2150, 0.34, 280, 50),
    ("Rice", "IR72", 2300, 0.47, 850, 200),
    ("Maize", "McCurdy 84aa", 2050, 0.50, 500, 50),
    ("Soybean", "Bragg", 2500, 0.35, 680, 300),
    ("Soybean", "Williams82", 2350, 0.40, 600, 200),
    ("Dry bean", "Porrillo Sintetico", 2700, 0.40, 450, 600),
    ("Peanut", "FLORUNNER", 3100, 0.35, 520, 550),
    ("Potato", "Sebago", 2400, 0.85, 500, 350),
    ("Potato", "Desiree", 2700, 0.80, 690, 400),
    ("Potato", "Zibaihua", 2500, 0.45, 690, 500),
    ("Potato", "Jinguan", 2400, 0.45, 690, 450),
    ("Potato", "Russet Burbank", 2300, 0.90, 500, 400),
    ("Potato", "Hilite Russet", 2500, 0.90, 480, 400),
    ("Cassava", "MCol-1684", 5400, 0.65, 650, 300),
    ("Tomato", "SunnySD", 2800, 0.68, 520, 400),
    ("Tomato", "Agriset761", 2300, 0.50, 550, 300),
    ("Sweetcorn", "GSS0966 sh2", 1900, 0.40, 500, 250),
    ("Greenbean", "Bronco Habit 1", 1600, 0.45, 370, 300),
    ("Carrot", "Kazan F1", 2450, 0.70, 550, 250),
    ("Cotton", "Deltapine77", 4600, 0.40, 680, 200),
    ("Banana", "Prata Ana", 6600, 0.19, 600, 400),
]
# --- Zhao et al. (2019) Table 1b: site soils: name, AWC, RCN, DDC, RZD (mm) --------------------------
_ZHAO_SOILS = [
    ("Maricopa USA wheat FACE", 0.12, 70, 0.3, 800),
    ("Lincoln New Zealand wheat", 0.18, 60, 0.7, 1200),
    ("Los Banos Philippines rice", 0.12, 70, 0.3, 400),
    ("Gainesville USA maize", 0.12, 70, 0.3, 1500),
    ("Gainesville USA soybean", 0.07, 60, 0.7, 800),
    ("Ames USA soybean", 0.14, 75, 0.6, 1900),
    ("Wooster USA soybean", 0.18, 75, 0.4, 2200),
    ("Gainesville USA dry bean", 0.08, 65, 0.5, 700),
    ("Gainesville USA peanut", 0.05, 65, 0.5, 1800),
    ("Canberra Australia potato", 0.12, 60, 0.65, 1500),
    ("Huhhot China potato", 0.12, 75, 0.6, 300),
    ("WuMeng China potato", 0.10, 70, 0.6, 300),
    ("Benton USA potato", 0.10, 64, 0.8, 1200),
    ("Palmira Colombia cassava", 0.13, 85, 0.4, 1500),
    ("Gainesville USA tomato", 0.19, 85, 0.1, 800),
    ("Bradenton USA tomato", 0.14, 66, 0.5, 1000),
    ("Citra USA sweetcorn", 0.25, 60, 0.7, 1500),
    ("Gainesville USA green bean", 0.08, 65, 0.5, 1000),
    ("Trzciana Poland carrot", 0.09, 75, 0.4, 500),
    ("Maricopa USA cotton", 0.12, 70, 0.3, 600),
    ("Campo Grande Brazil banana", 0.11, 70, 0.5, 1500),
]


def _species_from_row(name: str, values) -> Species:
    return Species(canonical_crop(name), *(float(v) for v in values))


def _build_library(source: str, species: dict[str, Species], cultivars: list[Cultivar],
                   soils: list[Soil]) -> CropLibrary:
    by_crop: dict[str, dict[str, Cultivar]] = {crop: {} for crop in species}
    for cultivar in cultivars:
        if cultivar.species not in by_crop:
            raise UnknownNameError(f"cultivar {cultivar.name!r} names unknown crop {cultivar.species!r} "
                                   f"in parameter source {source!r}")
        by_crop[cultivar.species][normalize_name(cultivar.name)] = cultivar
    return CropLibrary(source, species, by_crop, {normalize_name(s.name): s for s in soils})


def zhao2019_library() -> CropLibrary:
    """The canonical parameter source: Zhao et al. (2019) Tables 1a and 1b."""
    species = {canonical_crop(n): _species_from_row(n, v) for n, v in _ZHAO_SPECIES.items()}
    cultivars = [Cultivar(canonical_crop(c), n, float(t), float(h), float(a), float(b))
                 for c, n, t, h, a, b in _ZHAO_CULTIVARS]
    soils = [Soil(n, float(a), float(r), float(d), float(z)) for n, a, r, d, z in _ZHAO_SOILS]
    return _build_library("zhao2019", species, cultivars, soils)


def _read_table(path: Path) -> list[dict[str, str]]:
    if not path.is_file():
        raise FileNotFoundError(f"parameter table not found: {path}")
    with path.open(newline="", encoding="utf-8", errors="replace") as handle:
        rows = list(csv.DictReader(handle))
    # Header cells carry markers ('Species*', 'Cultivar.'): key them by their letters only.
    return [{re.sub(r"[^A-Za-z0-9_]", "", k): (v or "").strip() for k, v in row.items() if k} for row in rows]


def _number(row: dict[str, str], column: str, path: Path, line: int) -> float:
    try:
        return float(row[column])
    except (KeyError, ValueError):
        raise ValueError(f"{path}:{line}: column {column!r}: expected a number, "
                         f"got {row.get(column)!r}") from None


def simple_r_library(inputs_dir: str | Path) -> CropLibrary:
    """The SIMPLE v1.1 R distribution's own tables, read from ``<inputs_dir>/Input`` (or ``inputs_dir``)."""
    base = Path(inputs_dir)
    if (base / "Input").is_dir():
        base = base / "Input"
    species: dict[str, Species] = {}
    path = base / "Species parameter.csv"
    for line, row in enumerate(_read_table(path), start=2):
        values = [_number(row, c, path, line) for c in
                  ("Tbase", "Topt", "RUE", "I50maxH", "I50maxW", "MaxT", "ExtremeT", "CO2_RUE", "S_Water")]
        species[canonical_crop(row["Species"])] = _species_from_row(row["Species"], values)
    cultivars = []
    path = base / "Cultivar.csv"
    for line, row in enumerate(_read_table(path), start=2):
        cultivars.append(Cultivar(canonical_crop(row["Species"]), row["Cultivar"],
                                  *(_number(row, c, path, line) for c in ("Tsum", "HI", "I50A", "I50B"))))
    soils = []
    path = base / "Soil.csv"
    for line, row in enumerate(_read_table(path), start=2):
        soils.append(Soil(row["SoilName"], *(_number(row, c, path, line) for c in ("AWC", "RCN", "DDC", "RZD"))))
    return _build_library("simple_r", species, cultivars, soils)


PARAMETER_SOURCES = ("zhao2019", "simple_r")


def crop_library(source: str = "zhao2019", inputs_dir: str | Path | None = None) -> CropLibrary:
    """A parameter source by name: ``zhao2019`` (embedded) or ``simple_r`` (needs ``inputs_dir``)."""
    if source == "zhao2019":
        return zhao2019_library()
    if source == "simple_r":
        if inputs_dir is None:
            raise ValueError("parameter source 'simple_r' needs the SIMPLE inputs directory")
        return simple_r_library(inputs_dir)
    raise UnknownNameError(f"unknown parameter source {source!r}; known: {', '.join(PARAMETER_SOURCES)}")
