"""The weather generator: statistics against the observed Benton County data, determinism, physical limits,
the parameter file, and the fit-weather command. (Speed is a benchmark: ``crop-sim bench``.)"""

import argparse
import json
import subprocess
import sys
from dataclasses import fields, replace
from datetime import date
from pathlib import Path

import numpy as np
import pytest

from crop_sim_ros.usage import UsageError
from crop_sim_ros.weather.fit import add_arguments, fit_parameters, load_observed, monthly_statistics, run
from crop_sim_ros.weather.generator import (BENTON_PARAMETERS_FILE, GeneratorParameters, benton_parameters,
                                            clear_sky_radiation_mj_m2, conditional_field_names, generate_season,
                                            generate_seasons, generator_parameters, smooth_daily)
from crop_sim_ros.weather.series import VARIABLES, WeatherError

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
SEASON_START = date(2000, 4, 1)
SEASON_DAYS = 183
# April..September (0-based calendar months), the season generated and the months every file observes.
SEASON_MONTHS = slice(3, 9)
N_SEASONS = 500


@pytest.fixture(scope="module")
def observed():
    return load_observed(DATA)


@pytest.fixture(scope="module")
def generated():
    return generate_seasons(benton_parameters(), SEASON_START, SEASON_DAYS, N_SEASONS, seed=11)


@pytest.fixture(scope="module")
def statistics(observed, generated):
    obs, gen = monthly_statistics(observed), monthly_statistics(generated)
    return {name: (obs[name][SEASON_MONTHS], gen[name][SEASON_MONTHS]) for name in obs}


@pytest.mark.parametrize("name, tolerance", [("tmax_degc", 1.0), ("tmin_degc", 1.0)])
def test_monthly_mean_temperatures_within_1_degc(statistics, name, tolerance):
    obs, gen = statistics[name]
    assert np.all(np.isfinite(obs))
    np.testing.assert_allclose(gen, obs, atol=tolerance, rtol=0)


@pytest.mark.parametrize("name, relative", [("srad_mj_m2", 0.10), ("rain_total_mm", 0.25)])
def test_monthly_radiation_within_10_percent_and_rain_totals_within_25_percent(statistics, name, relative):
    obs, gen = statistics[name]
    assert np.all(obs > 0)
    np.testing.assert_allclose(gen, obs, rtol=relative, atol=0)


def test_wet_day_fraction_within_005(statistics):
    obs, gen = statistics["wet_fraction"]
    np.testing.assert_allclose(gen, obs, atol=0.05, rtol=0)


@pytest.mark.parametrize("name, relative", [("vap_hpa", 0.10), ("wind_m_s", 0.10)])
def test_vapour_pressure_and_wind_within_10_percent_where_observed(statistics, name, relative):
    obs, gen = statistics[name]
    np.testing.assert_allclose(gen, obs, rtol=relative, atol=0)


COLUMNS = {"tmax": "tmax_degc", "tmin": "tmin_degc", "srad": "srad_mj_m2"}


def _standardized_lag1(series_list, params, variable):
    """Lag-1 correlation, April-September, of (value - wet/dry mean curve) / wet/dry monthly sd."""
    mean_dry, mean_wet, sd_dry, sd_wet = conditional_field_names(variable)
    today, yesterday = [], []
    for s in series_list:
        wet = s.rain_mm >= params.wet_day_threshold_mm
        month = s.dates.astype("datetime64[M]").astype(int) % 12
        mean = np.where(wet, smooth_daily(getattr(params, mean_wet), s.dates),
                        smooth_daily(getattr(params, mean_dry), s.dates))
        sd = np.where(wet, np.array(getattr(params, sd_wet))[month], np.array(getattr(params, sd_dry))[month])
        residual = (getattr(s, COLUMNS[variable]) - mean) / sd
        in_season = (month[1:] >= 3) & (month[1:] <= 8)
        today.append(residual[1:][in_season])
        yesterday.append(residual[:-1][in_season])
    return np.corrcoef(np.concatenate(today), np.concatenate(yesterday))[0, 1]


@pytest.mark.parametrize("variable", ["tmax", "tmin", "srad"])
def test_day_to_day_persistence_matches_observed(observed, generated, variable):
    """The AR(1) reproduces the observed lag-1 autocorrelation of standardized anomalies (within 0.08: the
    correlation matrices are fitted over whole years, the check looks at April-September).

    (Raw anomalies from monthly means persist more in the observations than in the generator, 0.74 vs 0.60
    for TMAX, since real cool spells outlast the rain days; a known limit of WGEN-type generators.)
    """
    params = benton_parameters()
    obs = _standardized_lag1(observed, params, variable)
    gen = _standardized_lag1(generated, params, variable)
    assert obs > 0.25
    assert abs(gen - obs) < 0.08


def test_smooth_daily_curve_keeps_monthly_means_and_has_no_month_steps():
    monthly = benton_parameters().tmax_mean_dry_degc
    dates = np.datetime64("2001-01-01") + np.arange(365)
    daily = smooth_daily(monthly, dates)
    month = dates.astype("datetime64[M]").astype(int) % 12
    np.testing.assert_allclose([daily[month == m].mean() for m in range(12)], monthly, atol=0.15)
    assert np.max(np.abs(np.diff(daily))) < 0.5  # degC per day (spring warms ~0.3); monthly steps reach 7


def test_generated_weather_is_complete_and_physical(generated):
    params = benton_parameters()
    drawn = tuple(name for name in VARIABLES if name != "tavg_degc")  # the generator draws no mean temperature
    for series in generated:
        series.require(drawn)  # no NaN, no impossible value
        assert np.all(np.isnan(series.tavg_degc))
    tmax = np.array([s.tmax_degc for s in generated])
    tmin = np.array([s.tmin_degc for s in generated])
    srad = np.array([s.srad_mj_m2 for s in generated])
    assert np.all(np.isfinite(tmax)) and np.all(np.isfinite(tmin))
    assert np.all(tmin <= tmax)
    assert np.all(np.array([s.rain_mm for s in generated]) >= 0)
    assert np.all(np.array([s.wind_m_s for s in generated]) >= 0)
    assert np.all(np.array([s.vap_hpa for s in generated]) > 0)
    rso = clear_sky_radiation_mj_m2(generated[0].day_of_year, params.site.latitude_deg, params.site.elevation_m)
    assert np.all(srad >= 0.1) and np.all(srad <= rso + 1e-9)
    wet = np.array([s.rain_mm for s in generated]) > 0
    assert np.all(np.array([s.rain_mm for s in generated])[wet] >= params.wet_day_threshold_mm)


def _arrays(series):
    return np.array([getattr(series, name) for name in VARIABLES])


def test_same_seed_same_weather_other_seed_other_weather():
    params = benton_parameters()
    first = generate_seasons(params, SEASON_START, 60, 4, seed=3)
    again = generate_seasons(params, SEASON_START, 60, 4, seed=3)
    other = generate_seasons(params, SEASON_START, 60, 4, seed=4)
    for a, b, c in zip(first, again, other):
        np.testing.assert_array_equal(_arrays(a), _arrays(b))
        assert not np.allclose(_arrays(a), _arrays(c))
    assert not np.allclose(_arrays(first[0]), _arrays(first[1]))  # seasons of one draw differ too


def test_single_season_is_the_n_equals_1_case_and_names_its_seed():
    params = benton_parameters()
    one = generate_season(params, SEASON_START, SEASON_DAYS, seed=3)
    np.testing.assert_array_equal(_arrays(one),
                                  _arrays(generate_seasons(params, SEASON_START, SEASON_DAYS, 1, seed=3)[0]))
    assert one.source == "generator(benton, seed=3)"
    assert one.start == SEASON_START and len(one) == SEASON_DAYS
    assert generate_seasons(params, SEASON_START, 5, 2, seed=3)[1].source == "generator(benton, seed=3, season=1)"
    rng_a, rng_b = np.random.default_rng(8), np.random.default_rng(8)
    np.testing.assert_array_equal(_arrays(generate_season(params, SEASON_START, 30, rng_a)),
                                  _arrays(generate_season(params, SEASON_START, 30, rng_b)))


def test_parameters_json_round_trip_and_rejects_bad_files(tmp_path):
    params = benton_parameters()
    path = tmp_path / "params.json"
    params.to_json(path)
    assert GeneratorParameters.from_json(path) == params
    values = json.loads(path.read_text())
    values["p_wet_after_wet"][6] = 1.5
    path.write_text(json.dumps(values))
    with pytest.raises(WeatherError, match="p_wet_after_wet.*outside"):
        GeneratorParameters.from_json(path)
    values["p_wet_after_wet"] = values["p_wet_after_wet"][:11]
    path.write_text(json.dumps(values))
    with pytest.raises(WeatherError, match="12 finite monthly values"):
        GeneratorParameters.from_json(path)
    path.write_text("{not json")
    with pytest.raises(WeatherError, match="params.json"):
        GeneratorParameters.from_json(path)


# --- the committed parameters against a refit -------------------------------------------------------------
# A refit on another CPU differs from the committed file by up to ~1e-14 relative (numpy's SIMD kernels sum in
# another order), so the comparison has a tolerance; it is far tighter than any real change (1e-6 relative).
FIT_RELATIVE_TOLERANCE = 1e-10
FIT_ABSOLUTE_TOLERANCE_OF_FIELD_SCALE = 1e-12


def fitted_numbers(params: GeneratorParameters) -> dict[str, np.ndarray]:
    """Every number of ``params`` by field name (the site's too); the name and metadata are not numbers."""
    numbers = {f"site.{key}": np.array([getattr(params.site, key)])
               for key in ("latitude_deg", "longitude_deg", "elevation_m")}
    for item in fields(params):
        if item.name not in ("name", "site", "metadata"):
            numbers[item.name] = np.asarray(getattr(params, item.name), dtype=float)
    return numbers


def assert_same_fit(actual: GeneratorParameters, expected: GeneratorParameters) -> None:
    """``actual`` equals ``expected`` up to the cross-machine tolerance above, field by field."""
    assert (actual.name, actual.site.name) == (expected.name, expected.site.name)
    got = fitted_numbers(actual)
    for name, value in fitted_numbers(expected).items():
        np.testing.assert_allclose(got[name], value, rtol=FIT_RELATIVE_TOLERANCE,
                                   atol=FIT_ABSOLUTE_TOLERANCE_OF_FIELD_SCALE * np.max(np.abs(value)), err_msg=name)


def check_committed_parameters_are_the_fit(committed: GeneratorParameters, observed) -> None:
    """What the two tests below assert of the committed parameters (also run on nudged copies of them)."""
    assert_same_fit(fit_parameters(observed, "benton"), committed)
    sources = [item["source"] for item in committed.metadata["fitted_from"]]
    assert sources == ["agweathernet/benton_e_2000-04-01_2000-09-30.csv"] + [
        f"simple_r_inputs/Weather/WAPA{year}01.WTH" for year in (92, 93, 94, 95)]
    # Vapour pressure and wind exist April-September only: the other months copy the nearest one.
    assert committed.metadata["pooled_months"]["wind"]["Jan"] == ["Apr"]
    assert committed.metadata["pooled_months"]["wind"]["Nov"] == ["Sep"]
    assert committed.wind_scale_m_s[0] == pytest.approx(committed.wind_scale_m_s[3], rel=1e-12)


def test_committed_parameters_are_the_fit_of_the_reference_data(observed):
    check_committed_parameters_are_the_fit(benton_parameters(), observed)


def _nudged(value, rng, ulps: int):
    """``value`` (a number or nested lists of them) with each number moved by ``ulps`` ulps up or down at
    random; exact 0 and 1 stay (a probability or a correlation's diagonal)."""
    if isinstance(value, list):
        return [_nudged(v, rng, ulps) for v in value]
    if value in (0.0, 1.0):
        return value
    x, direction = float(value), (np.inf if rng.random() < 0.5 else -np.inf)
    for _ in range(ulps):
        x = float(np.nextafter(x, direction))
    return x


def nudged_parameters_file(source: Path, target: Path, ulps: int, seed: int) -> Path:
    """A copy of a parameter file with every number (metadata aside) moved by ``ulps`` ulps."""
    rng = np.random.default_rng(seed)
    values = json.loads(source.read_text())
    for key, value in values.items():
        if key == "site":
            values[key] = {k: v if isinstance(v, str) else _nudged(v, rng, ulps) for k, v in value.items()}
        elif key not in ("name", "metadata"):
            values[key] = _nudged(value, rng, ulps)
    target.write_text(json.dumps(values, indent=1))
    return target


def test_comparison_with_the_committed_fit_passes_a_few_ulps_and_fails_a_real_change(observed, tmp_path):
    nudged = GeneratorParameters.from_json(
        nudged_parameters_file(BENTON_PARAMETERS_FILE, tmp_path / "nudged.json", ulps=4, seed=0))
    committed = benton_parameters()
    moved = [name for name, value in fitted_numbers(nudged).items()
             if not np.array_equal(value, fitted_numbers(committed)[name])]
    assert len(moved) == len(fitted_numbers(committed))  # every field moved
    assert nudged.residual_lag0_correlation[1][1] == 1.0  # exact 1 kept
    check_committed_parameters_are_the_fit(nudged, observed)
    # A real change, 1e-6 relative on any single number, fails the comparison.
    fitted = fit_parameters(observed, "benton")
    for name, value in fitted_numbers(committed).items():
        changed = value.copy()
        changed.flat[np.argmin(np.abs(changed))] *= 1 + 1e-6  # the field's smallest value: the hardest case
        if name.startswith("site."):
            other = replace(committed, site=replace(committed.site, **{name[5:]: float(changed[0])}))
        elif changed.ndim == 0:
            other = replace(committed, **{name: float(changed)})
        else:
            other = replace(committed, **{name: changed.tolist()})
        with pytest.raises(AssertionError, match=name):
            assert_same_fit(fitted, other)


def test_fit_weather_command_writes_the_parameters_and_prints_the_table(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    out = tmp_path / "fitted.json"
    assert run(parser.parse_args(["--data", str(DATA), "--out", str(out), "--check-seasons", "20"])) == 0
    assert_same_fit(GeneratorParameters.from_json(out), benton_parameters())
    printed = capsys.readouterr().out
    assert "wind: Jan from Apr" in printed
    assert "Jul " in printed and "obs / gen" in printed
    with pytest.raises(UsageError, match="benton_e_2000-04-01_2000-09-30.csv: cannot read"):  # one line, exit 2
        run(parser.parse_args(["--data", str(tmp_path), "--out", str(tmp_path / "x.json")]))
    assert not (tmp_path / "x.json").exists()


def test_changing_a_parameter_changes_the_weather():
    params = benton_parameters()
    drier = replace(params, p_wet_after_dry=(0.0,) * 12, p_wet_after_wet=(0.0,) * 12)
    assert sum(s.rain_mm.sum() for s in generate_seasons(drier, SEASON_START, SEASON_DAYS, 20, seed=1)) == 0


def _delta_changed(change, params, value, neutral, name, kept, bad_values):
    """``change(params, value)``'s parameters (named ``name``) and 20 generated seasons of ``params`` and of them
    (seed 3), after checking that the neutral value returns ``params``, that the columns ``kept`` are drawn the
    same, and that each bad value is refused naming the change's argument."""
    assert change(params, neutral) is params
    changed = change(params, value)
    assert changed.name == name
    argument = change.__code__.co_varnames[1]
    for bad in bad_values:
        with pytest.raises((WeatherError, ValueError), match=argument):
            change(params, bad)
    base, other = (generate_seasons(p, SEASON_START, SEASON_DAYS, 20, seed=3) for p in (params, changed))
    for b, o in zip(base, other):
        for column in kept:
            np.testing.assert_array_equal(getattr(o, column), getattr(b, column))
        assert o.source.startswith(f"generator({name}, seed=3")
    return changed, base, other


def _penman_monteith_mean(seasons) -> float:
    return float(np.mean([s.et0_mm("penman_monteith").mean() for s in seasons]))


def test_a_warmed_generator_raises_the_temperatures_and_nothing_else_it_draws():
    from crop_sim_ros.weather.generator import warmed
    params = benton_parameters()
    assert warmed(params, -1.5).name == "benton-1.5C"
    warm, base, hot = _delta_changed(warmed, params, 4.0, 0.0, "benton+4C", ("rain_mm", "srad_mj_m2", "wind_m_s"),
                                     (10.5, float("nan"), "warm"))
    np.testing.assert_allclose(warm.tmin_mean_wet_degc, np.array(params.tmin_mean_wet_degc) + 4.0)
    for b, h in zip(base, hot):
        np.testing.assert_allclose(h.tmax_degc - b.tmax_degc, 4.0, atol=1e-9)
        np.testing.assert_allclose(h.tmin_degc - b.tmin_degc, 4.0, atol=1e-9)
        assert np.all(h.vap_hpa > b.vap_hpa)  # the dew-point depression is kept: moister air when warmer
    assert _penman_monteith_mean(hot) > _penman_monteith_mean(base)


def test_a_dried_generator_lowers_the_vapour_pressure_and_nothing_else_it_draws():
    from crop_sim_ros.weather.generator import dried, warmed
    params = warmed(benton_parameters(), 6.0)
    assert dried(benton_parameters(), -2).name == "benton-2DPD"
    dry, base, arid = _delta_changed(dried, params, 8.0, 0.0, "benton+6C+8DPD",
                                     ("tmax_degc", "tmin_degc", "rain_mm", "srad_mj_m2", "wind_m_s"),
                                     (-10.5, float("inf"), None))
    np.testing.assert_allclose(dry.dew_point_depression_mean_degc, np.array(params.dew_point_depression_mean_degc) + 8)
    assert dry.dew_point_depression_sd_degc == params.dew_point_depression_sd_degc
    for b, a in zip(base, arid):
        assert np.all(a.vap_hpa <= b.vap_hpa) and a.vap_hpa.mean() < 0.8 * b.vap_hpa.mean()
        # drier air: a larger vapour-pressure deficit (though more net long-wave loss, so not every day)
        assert a.et0_mm("penman_monteith").mean() > b.et0_mm("penman_monteith").mean()
    with pytest.raises(WeatherError, match="drying_degc: gainesville was fitted without humidity data"):
        dried(generator_parameters("gainesville"), 2.0)


def test_a_rain_scaled_generator_scales_every_rain_amount_and_nothing_else_it_draws():
    from crop_sim_ros.weather.generator import rain_scaled
    _, base, dry = _delta_changed(rain_scaled, benton_parameters(), 0.3, 1.0, "bentonx0.3R",
                                  ("tmax_degc", "tmin_degc", "srad_mj_m2", "vap_hpa", "wind_m_s"),
                                  (-0.1, 3.5, float("nan"), "dry"))
    assert sum(b.rain_mm.sum() for b in base) > 100
    for b, a in zip(base, dry):
        np.testing.assert_allclose(a.rain_mm, 0.3 * b.rain_mm, rtol=1e-12)  # the same wet days, 0.3 x the rain


def test_a_widened_generator_raises_tmax_and_lowers_tmin_by_half_the_widening_each():
    from crop_sim_ros.weather.generator import widened
    params = benton_parameters()
    assert widened(params, -1).name == "benton-1DTR"
    wide, base, desert = _delta_changed(widened, params, 4.0, 0.0, "benton+4DTR", ("rain_mm", "srad_mj_m2", "wind_m_s"),
                                        (10.5, float("nan"), "wide"))
    np.testing.assert_allclose(wide.tmin_mean_wet_degc, np.array(params.tmin_mean_wet_degc) - 2.0)
    np.testing.assert_allclose(wide.tmax_mean_dry_degc, np.array(params.tmax_mean_dry_degc) + 2.0)
    for b, w in zip(base, desert):
        # each day 2 degC hotter by day and colder by night, but for the rare day the draws cross (swapped)
        shifted = np.isclose(w.tmax_degc - b.tmax_degc, 2.0) & np.isclose(w.tmin_degc - b.tmin_degc, -2.0)
        assert shifted.mean() > 0.97
        np.testing.assert_allclose((w.tmax_degc + w.tmin_degc) / 2, (b.tmax_degc + b.tmin_degc) / 2, atol=1e-9)
        assert w.vap_hpa.mean() < b.vap_hpa.mean()  # the dew point follows TMIN down


def test_a_brightened_generator_scales_the_radiation_below_clear_sky_and_nothing_else_it_draws():
    from crop_sim_ros.weather.generator import MIN_SRAD_MJ_M2, brightened, clear_sky_radiation_mj_m2
    params = benton_parameters()
    sunny, base, bright = _delta_changed(brightened, params, 1.25, 1.0, "bentonx1.25S",
                                         ("tmax_degc", "tmin_degc", "rain_mm", "vap_hpa", "wind_m_s"),
                                         (0.4, 2.5, float("nan"), "sunny"))
    np.testing.assert_allclose(sunny.srad_sd_wet_mj_m2, 1.25 * np.array(params.srad_sd_wet_mj_m2))
    for b, s in zip(base, bright):
        day_of_year = np.array([d.timetuple().tm_yday for d in b.dates.astype(object)])
        cap = clear_sky_radiation_mj_m2(day_of_year, params.site.latitude_deg, params.site.elevation_m)
        # days the draw lies between the floor and clear sky, scaled or not: exactly 1.25 x
        below = (1.25 * b.srad_mj_m2 < cap - 1e-9) & (b.srad_mj_m2 > MIN_SRAD_MJ_M2)
        assert below.mean() > 0.3
        np.testing.assert_allclose(s.srad_mj_m2[below], 1.25 * b.srad_mj_m2[below], rtol=1e-9)
        assert np.all(s.srad_mj_m2 <= cap + 1e-9) and np.all(s.srad_mj_m2 >= b.srad_mj_m2)
    assert _penman_monteith_mean(bright) > _penman_monteith_mean(base)


def test_a_climate_name_gives_its_parameters_and_a_malformed_one_is_refused_by_name():
    from crop_sim_ros.weather.generator import (brightened, climate_name, climate_parameters, dried, rain_scaled,
                                                warmed, widened)
    for generator, warming, drying, rain, name in (
            ("benton", 0, 0, 1, "benton"), ("benton", 4, 0, 1, "benton+4C"), ("maricopa", -1.5, 0, 1, "maricopa-1.5C"),
            ("benton", 6, 8, 1, "benton+6C+8DPD"), ("benton", 0, 3, 1, "benton+3DPD"),
            ("benton", 6, 8, 0.3, "benton+6C+8DPDx0.3R"), ("gainesville", 0, 0, 2, "gainesvillex2R")):
        assert climate_name(generator, warming, drying, rain) == name
        expected = rain_scaled(dried(warmed(generator_parameters(generator), warming), drying), rain)
        assert climate_parameters(name) == expected and climate_parameters(name).name == name
    sunny = climate_name("benton", 6, 8, 0.3, radiation_factor=1.25)
    assert sunny == "benton+6C+8DPDx1.25Sx0.3R"
    assert climate_parameters(sunny) == rain_scaled(brightened(climate_parameters("benton+6C+8DPD"), 1.25), 0.3)
    desert = climate_name("benton", 4, 8, 0.3, 1.25, diurnal_range_degc=4)
    assert desert == "benton+4C+4DTR+8DPDx1.25Sx0.3R"
    assert climate_parameters(desert) == rain_scaled(brightened(dried(widened(warmed(benton_parameters(), 4), 4), 8),
                                                                1.25), 0.3)
    for bad in ("mars", "benton+4", "benton+4.0C", "benton+xC", "benton+8DPD+4C", "benton+11C", "gainesville+1DPD",
                "bentonx0.3", "bentonx0.30R", "bentonx4R", "bentonx0.3R+4C", "bentonx0.3Rx1.25S", "bentonx3S",
                "benton+8DPD+4DTR", "benton+11DTR"):
        with pytest.raises(WeatherError, match=r"climate|drying|warming|rain_factor|radiation_factor|diurnal_range"):
            climate_parameters(bad)


def test_a_spread_pool_draws_each_seasons_climate_and_sowing_date_from_its_ranges():
    from crop_sim_ros.weather.generator import (ClimateSpread, climate_parameters, generate_spread_seasons,
                                                generator_of_source)
    spread = ClimateSpread(warming_degc=(0, 8), drying_degc=(0, 10), rain_factor=(0.2, 1.0), sowing_delay_days=(0, 30))
    seasons = generate_spread_seasons("benton", spread, SEASON_START, SEASON_DAYS, 300, seed=5)
    climates = [generator_of_source(s.source) for s in seasons]
    assert seasons[7].source == f"generator({climates[7]}, seed=5, season=7)"
    params = [climate_parameters(c) for c in climates]  # each a climate the generator reads back by its name
    base = benton_parameters()
    warming = np.array([p.tmax_mean_dry_degc[0] - base.tmax_mean_dry_degc[0] for p in params])
    drying = np.array([p.dew_point_depression_mean_degc[0] - base.dew_point_depression_mean_degc[0] for p in params])
    rain = np.array([p.wet_day_threshold_mm / base.wet_day_threshold_mm for p in params])
    delay = np.array([(s.start - SEASON_START).days for s in seasons])
    for values, (least, most) in ((warming, (0, 8)), (drying, (0, 10)), (rain, (0.2, 1.0)), (delay, (0, 30))):
        assert least - 1e-9 <= values.min() < least + 0.1 * (most - least)  # spread over the whole range
        assert most - 0.1 * (most - least) < values.max() <= most + 1e-9
    # each season's weather is its climate's: a warmer draw is warmer, a drier one has lower vapour pressure
    tmax = np.array([s.tmax_degc.mean() for s in seasons])
    vap = np.array([s.vap_hpa.mean() for s in seasons])
    assert np.corrcoef(warming, tmax)[0, 1] > 0.5 and np.corrcoef(drying, vap)[0, 1] < -0.5
    same = generate_spread_seasons("benton", spread, SEASON_START, SEASON_DAYS, 300, seed=5)
    assert [s.source for s in same] == [s.source for s in seasons]
    np.testing.assert_array_equal(same[299].rain_mm, seasons[299].rain_mm)
    other = generate_spread_seasons("benton", spread, SEASON_START, SEASON_DAYS, 300, seed=6)
    assert other[0].source != seasons[0].source
    assert spread.describe() == ("+0 to +8 degC, dew-point depression +0 to +10 degC, rain x 0.2 to 1, sown 0 to 30 "
                                 "days later")
    assert ClimateSpread(warming_degc=(-2, 2), drying_degc=(1, 1)).describe() == (
        "-2 to +2 degC, dew-point depression +1 degC")
    fixed = ClimateSpread(warming_degc=(2, 2))
    assert {generator_of_source(s.source) for s in generate_spread_seasons("benton", fixed, SEASON_START, 10, 5, 1)} == {
        "benton+2C"}
    for bad, message in (({"warming_degc": (3, 1)}, "not a range"), ({"drying_degc": (0, 11)}, "drying_degc: 11"),
                         ({"rain_factor": (-1, 1)}, "rain_factor: -1"), ({"sowing_delay_days": (0, 2.5)}, "whole"),
                         ({"warming_degc": 3}, "expected \\[least, most\\]")):
        with pytest.raises(WeatherError, match=message):
            ClimateSpread(**bad)


def test_weather_layer_imports_no_ros_gym_or_torch():
    code = ("import sys, crop_sim_ros.weather.generator, crop_sim_ros.weather.fit, crop_sim_ros.weather.csv_readers\n"
            "print(sorted(m for m in ('rclpy', 'gymnasium', 'torch') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                            cwd=Path(__file__).resolve().parents[1])
    assert result.stdout.strip() == "[]"


def test_fit_weather_fits_only_the_named_files(tmp_path):
    """Naming only --dssat fits only those files: Benton's AgWeatherNet default is not mixed in, nor its site."""
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    out = tmp_path / "gainesville.json"
    gainesville = ["simple_r_inputs/Weather/UFGA7801.WTH", "simple_r_inputs/Weather/UFGA7901.WTH"]
    assert run(parser.parse_args(["--data", str(DATA), "--name", "g", "--dssat", *gainesville, "--out", str(out),
                                  "--check-seasons", "5"])) == 0
    fitted = GeneratorParameters.from_json(out)
    assert fitted.site.name == "UFGA"
    assert [entry["source"] for entry in fitted.metadata["fitted_from"]] == gainesville
