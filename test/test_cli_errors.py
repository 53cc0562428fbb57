"""Every mistake a user can make on the command line ends in one line on stderr, naming what is wrong, and
exit status 2, never a traceback: the real ``crop-sim`` console script of the venv, run as a user runs it."""

from __future__ import annotations

import subprocess
import sys
from datetime import date, timedelta
from pathlib import Path

import pytest

from policy_files import ppo_file

REPO = Path(__file__).resolve().parent.parent
CROP_SIM = Path(sys.executable).with_name("crop-sim")  # the console script beside this venv's python
SOWING = date(2000, 4, 1)
HEADER = "date,tmax_degc,tmin_degc,srad_mj_m2,rain_mm,vap_hpa,wind_m_s"
SITE_LINES = ["# latitude_deg: 46.2", "# longitude_deg: -119.2", "# elevation_m: 200"]
FIRST_DAY_LINE = len(SITE_LINES) + 2  # file line of the sowing day (after the site comments and the header)


def weather_lines(days: int = 160) -> list[str]:
    """A plain weather CSV (crop_sim_ros.weather.csv_readers), one line per day from SOWING."""
    rows = [f"{SOWING + timedelta(days=d)},{24 + d % 5},{9 + d % 3},{20 + d % 4},{5.0 if d % 7 == 0 else 0.0},12.0,2.0"
            for d in range(days)]
    return [*SITE_LINES, HEADER, *rows]


def scenario_yaml(weather: str, **fields) -> str:
    values = {"name": "custom", "sowing_date": str(SOWING), "max_season_days": 150, **fields}
    head = "".join(f"{key}: {value}\n" for key, value in values.items())
    return head + f"weather:\n  kind: file\n  path: {weather}\n  format: csv\n"


def replace_line(lines: list[str], number: int, text: str) -> list[str]:
    """``lines`` with file line ``number`` (1-based) replaced."""
    return [text if i == number - 1 else line for i, line in enumerate(lines)]


def day_line(day: int) -> int:
    return FIRST_DAY_LINE + day


def broken_weather(kind: str) -> tuple[bytes, str]:
    """(file content, a fragment the error must contain) for each kind of weather error."""
    lines = weather_lines()
    good_day_3 = lines[day_line(3) - 1]
    cases = {
        "not a number": (replace_line(lines, day_line(3), good_day_3.replace(",0.0,12.0", ",abc,12.0")),
                         f"line {day_line(3)}, column rain_mm: 'abc' is not a number"),
        "missing column": ([*SITE_LINES, HEADER.replace(",rain_mm", ""),
                            *[",".join(row.split(",")[:4] + row.split(",")[5:]) for row in lines[len(SITE_LINES) + 1:]]],
                           f"line {len(SITE_LINES) + 1}, column rain_mm: required column is missing"),
        "TMIN above TMAX": (replace_line(lines, day_line(10), f"{SOWING + timedelta(days=10)},5,15,20,0.0,12.0,2.0"),
                            f"line {day_line(10)}"),
        "a day missing": ([line for i, line in enumerate(lines) if i != day_line(20) - 1], "line"),
        "empty file": ([], "no column line"),
        "negative rain": (replace_line(lines, day_line(4), f"{SOWING + timedelta(days=4)},25,10,20,-3.0,12.0,2.0"),
                          f"line {day_line(4)}"),
        "NaN": (replace_line(lines, day_line(6), f"{SOWING + timedelta(days=6)},nan,10,20,0.0,12.0,2.0"),
                f"line {day_line(6)}"),
        "bad date": (replace_line(lines, day_line(2), good_day_3.replace(str(SOWING + timedelta(days=3)), "2000-13-45")),
                     f"line {day_line(2)}, column date: '2000-13-45' is not an ISO date"),
    }
    if kind == "UTF-16 without a byte-order mark":
        return ("\n".join(lines) + "\n").encode("utf-16-le"), "NUL characters: UTF-16 or UTF-32 text without"
    if kind == "Latin-1 bytes":
        text = "\n".join(replace_line(lines, 2, "# longitude_deg: -119.2 °W")) + "\n"
        return text.encode("latin-1"), "line 2: byte"
    content, fragment = cases[kind]
    return ("\n".join(content) + "\n" if content else "").encode(), fragment


WEATHER_ERRORS = ["not a number", "missing column", "TMIN above TMAX", "a day missing", "empty file", "negative rain",
                  "NaN", "bad date", "UTF-16 without a byte-order mark", "Latin-1 bytes"]


def run_crop_sim(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(CROP_SIM), *args], capture_output=True, text=True, timeout=300, cwd=cwd)


def assert_one_line_usage_error(done: subprocess.CompletedProcess, command: str, *fragments: str) -> None:
    lines = done.stderr.splitlines()
    assert done.returncode == 2 and len(lines) == 1, (done.returncode, done.stdout, done.stderr)
    assert lines[0].startswith(f"crop-sim {command}: "), lines[0]
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert "Traceback" not in done.stdout + done.stderr and done.stdout == ""


@pytest.mark.parametrize("kind", WEATHER_ERRORS)
def test_simulate_weather_errors_are_one_line_naming_file_and_line(tmp_path, kind):
    content, fragment = broken_weather(kind)
    weather = tmp_path / "weather.csv"
    weather.write_bytes(content)
    (tmp_path / "s.yaml").write_text(scenario_yaml(str(weather)))
    done = run_crop_sim("simulate", "--task", str(tmp_path / "s.yaml"), "--out", str(tmp_path / "out"),
                        cwd=tmp_path)
    assert_one_line_usage_error(done, "simulate", "--task: ", str(weather), fragment)
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_simulate_takes_a_scenario_yaml_path(tmp_path):
    (tmp_path / "weather.csv").write_text("\n".join(weather_lines()) + "\n")
    (tmp_path / "s.yaml").write_text(scenario_yaml(str(tmp_path / "weather.csv")))
    done = run_crop_sim("simulate", "--task", "s.yaml", "--irrigation-mm", "0,10", "--no-plot", "--out", "out",
                        cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    fields = __import__("json").loads((tmp_path / "out" / "summary.json").read_text())["fields"]
    assert [f["irrigation_mm_per_day"] for f in fields] == [0.0, 10.0]
    assert fields[1]["yield_t_ha"] > fields[0]["yield_t_ha"] > 0


def simulate_cases(tmp_path: Path) -> dict[str, tuple[list[str], tuple[str, ...]]]:
    weather = tmp_path / "weather.csv"
    weather.write_text("\n".join(weather_lines()) + "\n")
    (tmp_path / "a_file").write_text("not a directory")
    yamls = {
        "oversized.yaml": scenario_yaml(str(weather), max_season_days=20000),
        "many_seasons.yaml": ("name: many\nsowing_date: 2000-04-01\nmax_season_days: 150\n"
                              "weather:\n  kind: generator\n  n_seasons: 10000000\n"),
        "syntax.yaml": "name: [unclosed\nweather: {kind: file\n",
        "unknown_field.yaml": scenario_yaml(str(weather), colour="green"),
        "unknown_crop.yaml": scenario_yaml(str(weather), crop="mango"),
        "missing_weather.yaml": scenario_yaml(str(tmp_path / "absent.csv")),
    }
    for name, text in yamls.items():
        (tmp_path / name).write_text(text)
    scenario = ["--task"]
    return {
        "unknown scenario": ([*scenario, "atlantis"], ("--task: unknown scenario 'atlantis'; known: ",)),
        "missing data directory": ([*scenario, "benton-2000", "--data-dir", str(tmp_path / "absent")],
                                   ("--data-dir: ", "absent is not a directory")),
        "data directory without the file": ([*scenario, "benton-2000", "--data-dir", str(tmp_path)],
                                            ("--task: ", "benton_e_2000-04-01_2000-09-30.csv not found")),
        "output path is a file": (["--out", str(tmp_path / "a_file")], ("--out: ", "a_file is a file")),
        "oversized season": ([*scenario, str(tmp_path / "oversized.yaml")],
                             ("oversized.yaml: max_season_days: 20000 is not a whole number in 1..730",)),
        "too many generated seasons": ([*scenario, str(tmp_path / "many_seasons.yaml")],
                                       ("weather.n_seasons: 10000000 is not a whole number in 1..10000",)),
        "YAML syntax": ([*scenario, str(tmp_path / "syntax.yaml")], ("syntax.yaml: ", "line 2")),
        "unknown YAML field": ([*scenario, str(tmp_path / "unknown_field.yaml")], ("yaml: colour: unknown field (known: ",)),
        "unknown crop": ([*scenario, str(tmp_path / "unknown_crop.yaml")], ("mango",)),
        "missing weather file": ([*scenario, str(tmp_path / "missing_weather.yaml")], ("absent.csv not found",)),
        "missing YAML file": ([*scenario, str(tmp_path / "nowhere.yaml")], ("nowhere.yaml",)),
        "rate not a number": (["--irrigation-mm", "5,lots"], ("--irrigation-mm: '5,lots' is not",)),
        "rate out of range": (["--irrigation-mm", "200"], ("--irrigation-mm: every rate must be",)),
        "too many rates": (["--irrigation-mm", ",".join(["1"] * 1001)], ("1001 rates; at most 1000",)),
        "season out of range": (["--season", "1000"], ("--season: scenario 'benton-generated' has seasons 0..999",)),
    }


SIMULATE_CASES = ["unknown scenario", "missing data directory", "data directory without the file",
                  "output path is a file", "oversized season", "too many generated seasons", "YAML syntax",
                  "unknown YAML field", "unknown crop", "missing weather file", "missing YAML file",
                  "rate not a number", "rate out of range", "too many rates", "season out of range"]


@pytest.mark.parametrize("case", SIMULATE_CASES)
def test_simulate_user_errors_are_one_line_and_status_2(tmp_path, case):
    args, fragments = simulate_cases(tmp_path)[case]
    if "--out" not in args:
        args = [*args, "--out", str(tmp_path / "out")]
    done = run_crop_sim("simulate", *args, "--no-plot", cwd=tmp_path)
    assert_one_line_usage_error(done, "simulate", *fragments)


@pytest.fixture(scope="module")
def policy_files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("policies")
    (folder / "corrupt.zip").write_bytes(b"PK\x03\x04 this is not a policy")
    return {"wrong observation": ppo_file(folder / "obs5.zip", (5,)),
            "wrong action": ppo_file(folder / "act2.zip", (23,), (2,)),
            "corrupt": folder / "corrupt.zip", "missing": folder / "absent.zip"}


EVALUATE_CASES = {
    "seeds backwards": (["--seeds", "5..1"], ("--seeds: '5..1' runs backwards; write 1..5",)),
    "seeds not numbers": (["--seeds", "a..b"], ("--seeds: 'a..b' is neither",)),
    "too many seeds": (["--seeds", "0..99999999"], ("--seeds: 100000000 seeds; at most 10000",)),
    "no seeds": (["--seeds", ","], ("--seeds: no seeds in ','",)),
    "negative seed": (["--seeds=-3..2"], ("--seeds: seeds are non-negative, got -3",)),
    "unknown policy": (["--policies", "zero,clairvoyant"], ("--policies clairvoyant: unknown policy 'clairvoyant'",)),
    "unknown scenario": (["--seasons", "atlantis"], ("--seasons: unknown scenario 'atlantis'",)),
    "output path is a file": (["--out", "{a_file}"], ("--out: ", "a_file is a file")),
    "corrupt policy file": (["--policies", "ppo:{corrupt}"], ("corrupt.zip is not a Stable-Baselines3 PPO policy",)),
    "missing policy file": (["--policies", "ppo:{missing}"], ("absent.zip does not exist",)),
    "policy observing another shape": (["--policies", "ppo:{wrong observation}"],
                                       ("obs5.zip: its network observes Box of shape (5,), but the task's 'full' "
                                        "features are 23 values",)),
    "policy acting with another shape": (["--policies", "ppo", "--ppo-path", "{wrong action}"],
                                         ("act2.zip: its network acts with Box of shape (2,)",)),
}


@pytest.mark.parametrize("case", EVALUATE_CASES)
def test_evaluate_user_errors_are_one_line_and_status_2(tmp_path, policy_files, case):
    args, fragments = EVALUATE_CASES[case]
    (tmp_path / "a_file").write_text("not a directory")
    paths = {"a_file": tmp_path / "a_file", **policy_files}
    args = [a.format(**paths) if "{" in a else a for a in args]
    defaults = {"--out": str(tmp_path / "out"), "--seasons": "benton-generated", "--seeds": "0"}
    given = {a.split("=")[0] for a in args if a.startswith("--")}
    args += [item for key, value in defaults.items() if key not in given for item in (key, value)]
    done = run_crop_sim("evaluate", *args, "--no-plots", cwd=tmp_path)
    assert_one_line_usage_error(done, "evaluate", *fragments)


@pytest.mark.parametrize("kind", ["not a number", "TMIN above TMAX", "UTF-16 without a byte-order mark"])
def test_evaluate_weather_errors_are_one_line_naming_file_and_line(tmp_path, kind):
    content, fragment = broken_weather(kind)
    weather = tmp_path / "weather.csv"
    weather.write_bytes(content)
    (tmp_path / "s.yaml").write_text(scenario_yaml(str(weather)))
    done = run_crop_sim("evaluate", "--policies", "zero", "--seasons", str(tmp_path / "s.yaml"), "--seeds", "0",
                        "--no-plots", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert_one_line_usage_error(done, "evaluate", "--seasons: ", str(weather), fragment)


@pytest.mark.parametrize("args, fragment", [
    (["--seasons", "0"], "--seasons: 0 is not in 1..100000"),
    (["--seasons", "100001"], "--seasons: 100001 is not in 1..100000"),
    (["--policy-file", "absent.zip"], "--policy-file: absent.zip is not a file"),
    (["--timeout", "0"], "--timeout: 0.0 s is not positive"),
])
def test_farm_input_errors_are_refused_before_any_node_starts(tmp_path, args, fragment):
    done = run_crop_sim("farm", *args, cwd=tmp_path)
    assert_one_line_usage_error(done, "farm", fragment)
