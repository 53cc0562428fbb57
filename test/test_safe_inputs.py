"""Tiny hostile inputs stay tiny (issue 34, sections 1, 3 and 4): every YAML file a user gives is read by
crop_sim_ros.safe_yaml (a regular file, size-capped, no aliases, bounded nesting, no duplicate keys) and a
scenario file is checked by its strict schema, each refusal one line naming the file and the field, never what
another file holds; all in bounded memory and well under a second."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import subprocess
import sys
import threading
import time
import tracemalloc
from pathlib import Path

import pytest

from crop_agent_ros.cli import main
from crop_sim_ros.safe_yaml import CONFIG_MAX_BYTES, MAX_DEPTH, YamlInputError, loads, read_yaml
from crop_sim_ros.task.scenario import (MAX_BASE_CHAIN, SCENARIO_DIR, get_scenario, load_scenario, scenario_from_dict,
                                        scenario_names)
from crop_sim_ros.usage import UsageError

REPO = Path(__file__).resolve().parent.parent
# The commit whose scenario loader (plain PyYAML, checks by hand) every built-in must still agree with.
OLD_LOADER_COMMIT = "9209ddc"
MEMORY_LIMIT_BYTES = 100 * 1024 * 1024
# A 9^9-element "billion laughs" in the quota of a family scenario: ~400 bytes, 387 million strings expanded.
BOMB = ("name: bomb\nsowing_date: 2000-04-01\nweather: {kind: generator, n_seasons: 1}\neconomics: {}\n"
        "limits:\n  quota_mm: [&a0 [1,1,1,1,1,1,1,1,1]"
        + "".join(f",&a{i} [{','.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)) + "]\n")
GOOD = "name: custom\nsowing_date: 2000-04-01\nmax_season_days: 150\nweather: {kind: generator, n_seasons: 1}\n"


@pytest.fixture(scope="module", autouse=True)
def warm_command():
    """``crop-sim simulate`` run once before any is timed (its first run imports its modules)."""
    main(["simulate", "--task", "/nonexistent/none.yaml"])


def run_cli(argv: list[str], capsys, timeout: float = 10.0) -> tuple[int, str, float, int]:
    """``crop-sim ARGV`` in-process, in a thread that must end within ``timeout`` s: (exit status, stderr,
    seconds, peak bytes traced)."""
    result: dict = {}

    def target():
        try:
            result["status"] = main(argv)
        except BaseException as error:  # noqa: BLE001 - a traceback is what the test reports
            result["error"] = error
    tracemalloc.start()
    start = time.perf_counter()
    worker = threading.Thread(target=target, daemon=True)
    worker.start()
    worker.join(timeout)
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert not worker.is_alive(), f"crop-sim {' '.join(argv)} still running after {timeout} s"
    if "error" in result:
        raise result["error"]
    return result["status"], capsys.readouterr().err, seconds, peak


def refused(argv: list[str], capsys, *fragments: str, seconds: float = 1.0) -> str:
    """``crop-sim ARGV`` ends in one line with every fragment, exit 2, within ``seconds`` and 100 MB."""
    status, err, took, peak = run_cli(argv, capsys)
    assert status == 2, err
    assert err.endswith("\n") and err.count("\n") == 1, err
    for fragment in fragments:
        assert fragment in err, err
    assert took < seconds, f"{took:.2f} s"
    assert peak < MEMORY_LIMIT_BYTES, f"{peak / 2**20:.0f} MB"
    return err


def simulate(path: Path, tmp_path: Path) -> list[str]:
    return ["simulate", "--task", str(path), "--out", str(tmp_path / "out"), "--no-plot"]


# --- section 1: a few hundred bytes exhaust nothing --------------------------------------------------------

def test_an_alias_bomb_is_refused_by_simulate_in_one_line_within_a_second(tmp_path, capsys):
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(BOMB)
    assert len(BOMB) < 500
    err = refused(simulate(bomb, tmp_path), capsys, "crop-sim simulate: --task: ", f"{bomb}: line 6, column 14",
                  "anchors and aliases")
    assert "[1, 1" not in err


def test_an_alias_bomb_as_the_sim_nodes_scenario_parameter_is_refused_at_once(tmp_path):
    pytest.importorskip("rclpy")
    from crop_sim_ros.sim import EnvConfig, ScenarioFileError, build_scenario, scenario_error
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text(BOMB)
    config = EnvConfig(scenario=str(bomb), data_dir="", crop="", cultivar="", soil="", co2_ppm=-1.0,
                       noise_scale=1.0, irrigation_cost_per_mm=-1.25e-4)
    tracemalloc.start()
    start = time.perf_counter()
    with pytest.raises(ScenarioFileError) as caught:
        build_scenario(config)
    took, peak = time.perf_counter() - start, tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    message = scenario_error(config, caught.value)
    assert "anchors and aliases" in message and str(bomb) in message and "\n" not in message
    assert took < 1.0 and peak < MEMORY_LIMIT_BYTES


@pytest.mark.parametrize("kind", ["fifo", "link to /dev/zero", "directory"])
def test_a_scenario_that_is_not_a_regular_file_is_refused_unread(tmp_path, capsys, kind):
    path = tmp_path / "weird.yaml"
    if kind == "fifo":
        os.mkfifo(path)  # no writer: reading it would block for ever
    elif kind == "directory":
        path.mkdir()
    else:
        path.symlink_to("/dev/zero")
    refused(simulate(path, tmp_path), capsys, "crop-sim simulate: --task: ", f"{path}", "not a regular file")
    with pytest.raises(YamlInputError, match="not a regular file"):
        read_yaml(path)


def test_an_oversized_scenario_is_refused_before_it_is_read(tmp_path, capsys):
    path = tmp_path / "big.yaml"
    path.write_text(GOOD + "# padding\n" * (CONFIG_MAX_BYTES // 10))
    refused(simulate(path, tmp_path), capsys, f"{path}: ", "bytes, more than the 65,536 allowed")


def test_duplicate_keys_are_refused_with_their_line_and_column(tmp_path, capsys):
    path = tmp_path / "twice.yaml"
    path.write_text(GOOD + "limits: {quota_mm: 300, quota_mm: 100}\neconomics: {}\n")
    refused(simulate(path, tmp_path), capsys, f"{path}: line 5, column 25: duplicate key")
    with pytest.raises(YamlInputError, match="line 2, column 1: duplicate key"):
        loads("name: a\nname: b\n", "x.yaml")


def test_deep_nesting_is_refused_at_the_first_level_too_deep(tmp_path, capsys):
    path = tmp_path / "deep.yaml"
    path.write_text(GOOD + "description: " + "[" * 20_000 + "]" * 20_000 + "\n")
    refused(simulate(path, tmp_path), capsys, f"{path}: line 5, column 45: nested more than {MAX_DEPTH} levels deep")
    assert loads("a: " + "[" * (MAX_DEPTH - 1) + "]" * (MAX_DEPTH - 1), "x") is not None  # the mapping is one level


def test_a_syntax_error_names_the_place_without_quoting_the_file():
    with pytest.raises(YamlInputError) as caught:
        loads("key: [1, 2\nsecret: *hunter2_is_my_password\n", "x.yaml")
    assert "hunter2" not in str(caught.value) and str(caught.value).startswith("x.yaml: line ")


def test_the_checked_reader_reads_every_project_file_as_pyyaml_does():
    import yaml
    for path in sorted(SCENARIO_DIR.glob("*.yaml")):
        assert read_yaml(path) == yaml.safe_load(path.read_text(encoding="utf-8")), path
    for path in sorted((REPO / "crop_agent_ros" / "learning" / "hyperparams").glob("*.yml")):
        assert read_yaml(path, aliases=True) == yaml.safe_load(path.read_text(encoding="utf-8")), path
        with pytest.raises(YamlInputError, match="anchors and aliases"):
            read_yaml(path)  # the recipes' anchors: only the project's own files may use them


def test_hyperparameter_overrides_refuse_aliases_and_keep_plain_text():
    from crop_agent_ros.learning.hyperparameters import parse_overrides
    with pytest.raises(UsageError, match="--hyperparams 'net_arch': line 1, column 2: YAML anchors"):
        parse_overrides(["net_arch=[&a [64, 64], *a]"])
    with pytest.raises(UsageError, match="nested more than"):
        parse_overrides(["net_arch=" + "[" * 100 + "]" * 100])
    assert parse_overrides(["net_arch=[32, 32]", "note=a: b: c"]) == {"net_arch": [32, 32], "note": "a: b: c"}


def test_the_leaderboard_configuration_is_read_by_the_checked_reader(tmp_path):
    from crop_agent_ros.leaderboard import read_config
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "leaderboard.yaml").write_text("tasks: &t []\nagain: *t\n")
    with pytest.raises(UsageError, match=r"^results/leaderboard.yaml: line 1, column 8: YAML anchors"):
        read_config(tmp_path)


# --- section 3: a base file's contents never leak ----------------------------------------------------------

@pytest.mark.parametrize("secrets", ["DB_PASSWORD=secret\nAPI_TOKEN=secret\n", "DB_PASSWORD: secret\nname: x\n",
                                     "- secret\n", "DB_PASSWORD: [secret\n"])
def test_a_base_that_is_not_a_scenario_is_named_never_quoted(tmp_path, capsys, secrets):
    (tmp_path / ".env").write_text(secrets)
    path = tmp_path / "derived.yaml"
    path.write_text("base: .env\nname: derived\n")
    err = refused(simulate(path, tmp_path), capsys, f"{path}: base: {tmp_path / '.env'}")
    assert "secret" not in err


def test_a_base_that_is_not_a_scenario_is_not_quoted_to_a_sim_node_peer(tmp_path):
    pytest.importorskip("rclpy")
    from crop_sim_ros.sim import EnvConfig, build_scenario, scenario_error
    (tmp_path / "app.env").write_text("DB_PASSWORD=secret\n")
    path = tmp_path / "derived.yaml"
    path.write_text("base: app.env\nname: derived\n")
    config = EnvConfig(scenario=str(path), data_dir="", crop="", cultivar="", soil="", co2_ppm=-1.0,
                       noise_scale=1.0, irrigation_cost_per_mm=-1.25e-4)
    with pytest.raises(ValueError) as caught:
        build_scenario(config)
    message = scenario_error(config, caught.value)
    assert "app.env is not a scenario file" in message and "secret" not in message


def test_a_base_chain_is_at_most_32_files_and_never_a_cycle(tmp_path, capsys):
    for i in range(1200):
        (tmp_path / f"s{i}.yaml").write_text(f"base: s{i + 1}.yaml\n" if i < 1199 else GOOD)
    refused(simulate(tmp_path / "s0.yaml", tmp_path), capsys,
            f"base: a chain of more than {MAX_BASE_CHAIN} scenario files")
    (tmp_path / "s1199.yaml").write_text(GOOD)
    (tmp_path / "s30.yaml").write_text("base: s0.yaml\n")  # 31 files, a cycle
    refused(simulate(tmp_path / "s0.yaml", tmp_path), capsys, "is a cycle")
    (tmp_path / "s30.yaml").write_text("base: s1199.yaml\n")  # 32 files: allowed
    assert load_scenario(tmp_path / "s0.yaml").name == "custom"


# --- section 4: a scenario file is checked by its schema --------------------------------------------------

SCHEMA_CASES = {
    "bool as capacity": ("limits: {capacity_mm_per_day: false}\neconomics: {}\n",
                         "limits.capacity_mm_per_day: false is not a finite number in [0, 1000]"),
    "bool as quota": ("limits: {quota_mm: true}\neconomics: {}\n", "limits.quota_mm: true is not a finite number"),
    "string as quota": ("limits: {quota_mm: '300'}\neconomics: {}\n", "limits.quota_mm: '300' is not a finite number"),
    "string as a whole number": ("limits: {nominal_season_days: '150'}\neconomics: {}\n",
                                 "limits.nominal_season_days: '150' is not a whole number in 1..366"),
    "huge noise": ("noise: {paw_mm: 1e39}\n", "noise.paw_mm: 1e+39 is not a finite number in [0, 1e+06]"),
    "NaN elevation": ("site: {name: s, latitude_deg: 46, longitude_deg: -119, elevation_m: .nan}\n",
                      "site.elevation_m: nan is not a finite number in [-500, 9000]"),
    "1e6 m elevation": ("site: {name: s, latitude_deg: 46, longitude_deg: -119, elevation_m: 1.0e6}\n",
                        "site.elevation_m: 1000000.0 is not a finite number in [-500, 9000]"),
    "latitude out of range": ("site: {name: s, latitude_deg: 91, longitude_deg: -119, elevation_m: 200}\n",
                              "site.latitude_deg: 91 is not a finite number in [-90, 90]"),
    "crop a number": ("crop: 5\n", "crop: expected text"),
    "unknown field": ("colour: green\n", "colour: unknown field (known: co2_ppm, crop"),
    "unknown kind": ("weather: {kind: magic}\n",
                     "weather.kind: 'magic' is not one of generator, file, seasons, mixture"),
}


@pytest.mark.parametrize("case", SCHEMA_CASES)
def test_each_schema_error_is_one_line_naming_the_field(tmp_path, capsys, case):
    text, expected = SCHEMA_CASES[case]
    path = tmp_path / "bad.yaml"
    path.write_text(GOOD.replace("weather: {kind: generator, n_seasons: 1}\n", "")
                    + ("" if text.startswith("weather") else "weather: {kind: generator, n_seasons: 1}\n") + text)
    refused(simulate(path, tmp_path), capsys, f"crop-sim simulate: --task: {path}: ", expected)


@pytest.mark.parametrize("missing, expected", [("name", "name: missing (required)"),
                                               ("kind", "weather.kind: missing (required)")])
def test_a_missing_name_or_weather_kind_is_named(tmp_path, capsys, missing, expected):
    path = tmp_path / "bad.yaml"
    path.write_text(GOOD.replace("name: custom\n", "") if missing == "name" else GOOD.replace("kind: generator, ", ""))
    refused(simulate(path, tmp_path), capsys, expected)


def test_one_error_lists_every_problem_with_its_path():
    with pytest.raises(ValueError) as caught:
        scenario_from_dict({"name": "x", "weather": {"kind": "generator", "n_seasons": True},
                            "limits": {"quota_mm": "300", "capacity_mm_per_day": False}, "crop": 5, "colour": 1})
    message = str(caught.value)
    for fragment in ("weather.n_seasons: true is not a whole number", "limits.quota_mm: '300'",
                     "limits.capacity_mm_per_day: false", "crop: expected text", "colour: unknown field"):
        assert fragment in message, message
    assert "\n" not in message


def test_an_integer_latitude_is_a_float_and_gives_the_same_yield(tmp_path, capsys):
    yields = []
    for latitude in ("46", "46.0"):
        path = tmp_path / f"site{latitude}.yaml"
        path.write_text(f"base: benton-generated\nname: site\nweather: {{kind: generator, n_seasons: 1}}\n"
                        f"site: {{name: s, latitude_deg: {latitude}, longitude_deg: -119, elevation_m: 200}}\n")
        assert load_scenario(path).site.latitude_deg == 46.0
        out = tmp_path / f"out{latitude}"
        assert main(["simulate", "--task", str(path), "--out", str(out), "--no-plot"]) == 0, capsys.readouterr().err
        yields.append([row["yield_t_ha"] for row in json.loads((out / "summary.json").read_text())["fields"]])
    assert yields[0] == yields[1] and all(y > 0 for y in yields[0])


def _old_loader():
    """The scenario loader of OLD_LOADER_COMMIT reading today's built-in files, or None without that history."""
    try:
        source = subprocess.run(["git", "-C", str(REPO), "show", f"{OLD_LOADER_COMMIT}:crop_sim_ros/task/scenario.py"],
                                capture_output=True, text=True, timeout=30, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    name = "crop_sim_ros.task._scenario_before_schema"
    spec = importlib.util.spec_from_loader(name, loader=None)
    module = importlib.util.module_from_spec(spec)
    module.__package__, module.__file__ = "crop_sim_ros.task", str(SCENARIO_DIR.parent / "scenario.py")
    sys.modules[name] = module
    try:
        exec(compile(source, f"{OLD_LOADER_COMMIT}:scenario.py", "exec"), module.__dict__)  # noqa: S102
    except ImportError:  # the old module no longer fits today's package: nothing to compare with
        return None
    finally:
        sys.modules.pop(name, None)
    return module


def test_every_built_in_scenario_loads_to_the_same_values_as_before_the_schema(shared_data):
    old = _old_loader()
    if old is None:
        pytest.skip(f"the loader of {OLD_LOADER_COMMIT} is not available in this checkout")
    for name in scenario_names():
        new_scenario = get_scenario(name, shared_data)
        old_scenario = old.load_scenario(SCENARIO_DIR / f"{name}.yaml", shared_data)
        assert repr(dataclasses.asdict(new_scenario)) == repr(dataclasses.asdict(old_scenario)), name


def test_a_number_too_long_for_python_is_refused_in_one_line(capsys):
    digits = "9" * 5000  # past Python's 4,300-digit limit of int()
    with pytest.raises(YamlInputError, match=r"^--hyperparams timesteps: a number too long to read$"):
        loads(digits, "--hyperparams timesteps")
    assert main(["train", "--task", "benton-quota", "--algorithm", "ppo", "--show",
                 "--hyperparams", f"timesteps={digits}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("crop-sim train: ") and digits not in err
