"""msg_examples/: every topic, service and action of the farm has an example, each example fills the real
message type as ``ros2 topic pub`` / ``ros2 service call`` / ``ros2 action send_goal`` would (rosidl_runtime_py's
``set_message_fields`` on ``yaml.safe_load``'s values; where rosidl_runtime_py is not installed, a port of that
function that takes and refuses the same values: a byte field such as DiagnosticStatus.level takes
``!!binary``, not the ``"\x01"`` that ``ros2 topic echo`` prints), matches what the node publishes (types,
the observation's labels), the examples agree with each other (the command of irrigation.yaml is for the day
the reset of reset.yaml starts on, stamped with its farm time, step.yaml's answer is the next day, and
step_result, crop_state and the weather examples are that day), and their values are the offline environment's."""

from __future__ import annotations

import array
import copy
import importlib
import math
import shlex
from datetime import date
from pathlib import Path

import numpy as np
import pytest
import yaml


from crop_sim_interfaces.action import RunSeason  # noqa: E402
from crop_sim_interfaces.msg import (CropState, FarmTerms, Forecast, IrrigationCommand, IrrigationStatus,  # noqa: E402
                                     StepResult, Weather)
from crop_sim_interfaces.srv import Reset, Step  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from crop_sim_ros import ros_interface as ri  # noqa: E402
from crop_sim_ros.task import IrrigationEnv  # noqa: E402
from crop_sim_ros.task.layout import EXTENDED, PAPER, WEATHER_NAMES  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "msg_examples"
FILES = sorted(EXAMPLES.glob("*.yaml"))

# every name the simulator serves -> (kind, interface type, the labels it uses, if any)
INTERFACE = {
    "/crop_sim/observation": ("topic", "std_msgs/msg/Float32MultiArray", ri.OBSERVATION_LABELS),
    "/crop_sim/crop_state": ("topic", "crop_sim_interfaces/msg/CropState", None),
    "/crop_sim/weather/today": ("topic", "crop_sim_interfaces/msg/Weather", None),
    "/crop_sim/weather/forecast": ("topic", "crop_sim_interfaces/msg/Forecast", None),
    "/crop_sim/step_result": ("topic", "crop_sim_interfaces/msg/StepResult", None),
    "/crop_sim/farm_terms": ("topic", "crop_sim_interfaces/msg/FarmTerms", None),
    "/crop_sim/irrigation": ("topic", "crop_sim_interfaces/msg/IrrigationCommand", None),
    "/crop_sim/irrigation_step": ("topic", "crop_sim_interfaces/msg/IrrigationCommand", None),
    "/crop_sim/irrigation_status": ("topic", "crop_sim_interfaces/msg/IrrigationStatus", None),
    "/diagnostics": ("topic", "diagnostic_msgs/msg/DiagnosticArray", None),
    "/clock": ("topic", "rosgraph_msgs/msg/Clock", None),
    "/crop_sim/step": ("service", "crop_sim_interfaces/srv/Step", None),
    "/crop_sim/reset": ("service", "crop_sim_interfaces/srv/Reset", None),
    "/crop_agent/run_season": ("action", "crop_sim_interfaces/action/RunSeason", None),
}


def interface_class(name: str):
    """'std_msgs/msg/Float64MultiArray' -> the Python class."""
    package, kind, type_name = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), type_name)


def _port_of_set_message_fields(msg, values) -> None:
    """rosidl_runtime_py.set_message.set_message_fields (Jazzy) without its 'auto'/'now' stamps: what
    ``ros2 topic pub`` does with the YAML values. A field takes a value of its own Python type as is; otherwise
    ``type(value)``, and if that raises TypeError a nested message filled from a mapping (so a byte field given
    a str fails: "expected to be a dictionary but is a str")."""
    from rosidl_parser.definition import AbstractNestedType, NamespacedType

    try:
        items = values.items()
    except AttributeError:
        raise TypeError(f"Value '{values}' is expected to be a dictionary but is a {type(values).__name__}") from None
    slot_types = dict(zip(msg.get_fields_and_field_types(), msg.SLOT_TYPES))
    for field_name, field_value in items:
        field = getattr(msg, field_name)  # AttributeError for a field the type does not have
        field_type = type(field)
        if field_type is array.array:
            value = field_type(field.typecode, field_value)
        elif field_type is np.ndarray:
            value = np.array(field_value, dtype=field.dtype)
        elif type(field_value) is field_type:
            value = field_value
        else:
            try:
                value = field_type(field_value)
            except TypeError:
                value = field_type()
                _port_of_set_message_fields(value, field_value)
        rosidl_type = slot_types[field_name]
        if isinstance(rosidl_type, AbstractNestedType) and isinstance(rosidl_type.value_type, NamespacedType):
            element = interface_class("/".join(rosidl_type.value_type.namespaced_name()))
            for n in range(len(value)):
                submessage = element()
                _port_of_set_message_fields(submessage, value[n])
                value[n] = submessage
        setattr(msg, field_name, value)


try:
    from rosidl_runtime_py.set_message import set_message_fields
except ImportError:  # not on PyPI: the port above
    set_message_fields = _port_of_set_message_fields


def fill(message, values, where: str = "message"):
    """``message`` with its fields set from YAML values as ``ros2 topic pub`` sets them (on a copy: the function
    replaces the mappings of a list of messages by messages, in place)."""
    try:
        set_message_fields(message, copy.deepcopy(values))
    except (TypeError, AttributeError, ValueError, AssertionError) as error:
        raise type(error)(f"{where}: {error}") from None
    return message


def plain(message):
    """Message -> plain YAML data, as ``ros2 topic echo`` prints it."""
    if hasattr(message, "get_fields_and_field_types"):
        return {key: plain(getattr(message, key)) for key in message.get_fields_and_field_types()}
    if isinstance(message, bytes):
        return message.decode("latin-1")
    if isinstance(message, (list, tuple)) or type(message).__name__ in ("array", "ndarray"):
        return [plain(v) for v in message]
    return message


def same(a, b) -> bool:
    """Plain message data equal, NaN equal to NaN (a paper task's money terms)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def test_every_topic_service_and_action_has_one_example():
    names = [yaml.safe_load(path.read_text())["name"] for path in FILES]
    assert sorted(names) == sorted(INTERFACE), "one msg_examples/*.yaml per topic, service and action"


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_example_fills_the_real_type(path):
    example = yaml.safe_load(path.read_text())
    kind, type_name, labels = INTERFACE[example["name"]]
    assert example["kind"] == kind and example["type"] == type_name
    cls = interface_class(type_name)
    if kind == "topic":
        messages = [example["message"]] + [example[k] for k in ("any_message", "rejected_message", "family_message")
                                           if k in example]
        for values in messages:
            message = fill(cls(), values)
            again = deserialize_message(serialize_message(message), cls)
            assert same(plain(again), plain(message))
        first = fill(cls(), example["message"])
        # what `ros2 topic echo` shows is the same message
        assert same(yaml.safe_load(example["echo"].removesuffix("---\n")), plain(first))
        if hasattr(first, "header") and example["name"] != "/diagnostics":  # the farm's typed state: stamped
            assert first.header.frame_id == "farm" and first.header.stamp.sec > 0
        if labels is not None:
            dim = first.layout.dim[0]
            assert dim.label == ",".join(labels) and dim.size == len(labels) == len(first.data)
        if type_name.endswith("Float32MultiArray"):
            obs = ri.observation_from_message(first)
            assert obs.dtype == np.float32 and obs.shape == (PAPER.size,)
        if example["name"] == "/diagnostics":  # the node's one status, named after the node
            (node_status,) = first.status
            (status,) = ri.node_statuses(first, "/crop_sim")
            assert [kv.key for kv in node_status.values] == list(ri.NODE_STATUS_KEYS)
            assert status["level"] == 1 and status["days_without_command"] == status["day"] - 1
        elif type_name.endswith("IrrigationStatus"):
            assert first.fate == IrrigationStatus.ACCEPTED and first.command.irrigation_mm == 12.5
            assert first.command.header == first.header and math.isnan(first.applied_mm)
        if example["command"].startswith("ros2 topic pub"):  # the command publishes the example as it stands
            *_, topic, type_arg, payload = shlex.split(example["command"])
            assert (topic, type_arg) == (example["name"], type_name)
            assert plain(fill(cls(), yaml.safe_load(payload), "command")) == plain(first)
        if example["name"] in ("/crop_sim/irrigation", "/crop_sim/irrigation_step"):
            assert 0 <= first.irrigation_mm <= 100 and first.episode != IrrigationCommand.ANY_EPISODE
            assert example["command"].startswith("ros2 topic pub")
    elif kind == "service":
        *_, service, type_arg, payload = shlex.split(example["command"])
        assert (service, type_arg) == (example["name"], type_name)
        request = fill(cls.Request(), example["request"], "request")
        assert plain(fill(cls.Request(), yaml.safe_load(payload), "command")) == plain(request)
        response = fill(cls.Response(), example["response"], "response")
        again = deserialize_message(serialize_message(response), cls.Response)
        assert same(plain(again), plain(response)) and response.success and response.message == ""
        observation = np.asarray(response.observation, dtype=np.float32)
        assert observation.shape == (PAPER.size,)
        assert np.array_equal(observation.astype(np.float64), example["response"]["observation"]), "exact float32"
        if "failure_response" in example:
            failure = fill(cls.Response(), example["failure_response"], "failure_response")
            assert not failure.success and failure.message
    else:
        *_, action, type_arg, payload = shlex.split(example["command"].replace("--feedback ", ""))
        assert (action, type_arg) == (example["name"], type_name)
        goal = fill(cls.Goal(), example["goal"], "goal")
        assert plain(fill(cls.Goal(), yaml.safe_load(payload), "command")) == plain(goal)
        feedback = fill(cls.Feedback(), example["feedback"], "feedback")
        result = fill(cls.Result(), example["result"], "result")
        assert feedback.step.day == 1 and result.success and result.days > feedback.step.day


def test_family_examples_are_a_benton_quota_season():
    """The family observation and the family farm terms: benton-quota, seed 0 (the observation on day 1 after
    20 mm, the pivot's 8 mm applied), as the offline environment gives them; labels from the extended layout."""
    env = IrrigationEnv("benton-quota")
    _, reset_info = env.reset(seed=0)
    obs, _, _, _, info = env.step(20.0)
    family = fill(interface_class("std_msgs/msg/Float32MultiArray")(),
                  yaml.safe_load((EXAMPLES / "observation.yaml").read_text())["family_message"])
    assert family.layout.dim[0].label == ",".join(EXTENDED.labels) and family.layout.dim[0].size == 29
    assert ri.observation_from_message(family, EXTENDED).tobytes() == obs.tobytes()
    terms = fill(FarmTerms(), _example("farm_terms")["family_message"])
    assert [getattr(terms, name) for name in ri.TERM_FIELDS] == [
        info["yield_value_per_t"] * env.scenario.economics.tuber_dry_matter_fraction, info["water_cost_per_mm"], 0.0,
        info["quota_mm"], 8.0]
    assert (terms.scenario, terms.seed, terms.sowing_date, terms.reward_unit) == ("benton-quota", 0,
                                                                                 reset_info["date"], "USD/ha")
    assert info["irrigation_applied_mm"] == 8.0 and obs[EXTENDED.index("irrigation_yesterday_mm")] == 8.0


def _example(name: str) -> dict:
    return yaml.safe_load((EXAMPLES / f"{name}.yaml").read_text())


def test_the_examples_tell_one_story_reset_command_status_step_clock():
    """reset.yaml starts episode E on day 0; irrigation.yaml and irrigation_step.yaml command that day (a
    command for day 1 right after a reset is refused: "day 1 is in the future"); irrigation_status.yaml accepts
    it as command #k and refuses one for the future; step.yaml applies #k and answers day 1, one day after the
    reset's date, which /clock (clock.yaml), step_result.yaml, crop_state.yaml and the weather examples show;
    farm_terms.yaml is the reset's terms. The values are the offline environment's (benton-generated, seed 0,
    12.5 mm on day 0)."""
    reset = fill(Reset.Response(), _example("reset")["response"])
    step = fill(Step.Response(), _example("step")["response"])
    terms, result = reset.terms, step.result
    episode, sowing = terms.episode, date.fromisoformat(terms.sowing_date)
    assert same(plain(terms), plain(fill(FarmTerms(), _example("farm_terms")["message"])))
    assert plain(result) == plain(fill(StepResult(), _example("step_result")["message"]))
    command = fill(IrrigationCommand(), _example("irrigation")["message"])
    day_0 = ri.sim_time(sowing, 0)
    assert (command.day, command.irrigation_mm, command.episode, command.header.stamp) == (0, 12.5, episode, day_0)
    assert command == fill(IrrigationCommand(), _example("irrigation_step")["message"])
    by_hand = fill(IrrigationCommand(), _example("irrigation")["any_message"])
    assert (by_hand.header.stamp.sec, by_hand.header.frame_id, by_hand.episode) == (0, "", -1)
    status_example = _example("irrigation_status")
    accepted = fill(IrrigationStatus(), status_example["message"])
    assert accepted.fate == IrrigationStatus.ACCEPTED and accepted.command == command
    assert (accepted.current_day, accepted.episode, accepted.header) == (0, episode, command.header)
    assert accepted.message == f"accepted 12.5 mm for day 0 (episode {episode})"
    refused = fill(IrrigationStatus(), status_example["rejected_message"])
    assert refused.fate == IrrigationStatus.REFUSED and refused.current_day == 0 and refused.command.day == 1
    assert refused.command.header.stamp == ri.sim_time(sowing, 1) and refused.header == accepted.header
    assert refused.message == "rejected: day 1 is in the future: the current day is 0"
    assert refused.sequence == accepted.sequence + 1
    assert (result.episode, result.day, result.irrigation_mm) == (episode, 1, 12.5)
    assert result.command_sequence == accepted.sequence
    day_1 = ri.sim_time(sowing, 1).sec
    assert _example("clock")["message"]["clock"]["sec"] == day_1 == result.header.stamp.sec
    assert terms.header.stamp.sec == ri.sim_time(sowing, 0).sec

    # the offline environment's numbers
    env = IrrigationEnv("benton-generated")
    obs0, info0 = env.reset(seed=0)
    obs1, reward, _, _, info1 = env.step(12.5)
    assert np.asarray(reset.observation, np.float32).tobytes() == obs0.tobytes()
    assert np.asarray(step.observation, np.float32).tobytes() == obs1.tobytes()
    assert (terms.scenario, terms.seed, terms.sowing_date, terms.weather_source) == (
        "benton-generated", 0, info0["date"], info0["weather_source"])
    assert terms.potential_yield_t_ha == info0["potential_yield_t_ha"] and math.isnan(terms.tuber_price_usd_per_t)
    assert result.reward == reward == result.episode_return
    wide = obs1.astype(np.float64).tolist()
    crop = fill(CropState(), _example("crop_state")["message"])
    assert (crop.episode, crop.day, crop.header.stamp.sec) == (episode, 1, day_1)
    assert (crop.biomass_t_ha, crop.thermal_time_degc_d, crop.paw_mm) == (
        wide[ri.OBS_BIOMASS], wide[ri.OBS_THERMAL_TIME], wide[ri.OBS_PAW])
    assert (crop.canopy_fsolar, crop.mature) == (info1["fsolar"], False)
    today = fill(Weather(), _example("weather_today")["message"])
    assert today.day == 1 and ri.weather_of(today) == wide[ri.OBS_TODAY]
    forecast = fill(Forecast(), _example("weather_forecast")["message"])
    assert forecast.weather.day == 2 and ri.weather_of(forecast.weather) == wide[ri.OBS_FORECAST]
    assert forecast.weather.header.stamp.sec == ri.sim_time(sowing, 2).sec and forecast.header.stamp.sec == day_1
    assert [getattr(forecast, name) for name in ri.FORECAST_SD_FIELDS] == [
        getattr(env.scenario.noise, name) for name in WEATHER_NAMES]


def test_the_run_season_example_is_the_refill_policy_season_of_its_seed():
    """run_season.yaml: the agent's refill policy over the season of seed 0 (the offline environment's), the
    feedback its first day, in the episode after step.yaml's."""
    from crop_agent_ros.ros.agent import make_agent_policy

    example = _example("run_season")
    goal, feedback = example["goal"], fill(RunSeason.Feedback(), example["feedback"])
    result = fill(RunSeason.Result(), example["result"])
    policy = make_agent_policy(goal["policy"])
    env = IrrigationEnv("benton-generated")
    obs, info = env.reset(seed=goal["seed"])
    policy.reset(goal["seed"])
    water = total = 0.0
    days, done, first = 0, False, None
    while not done:
        mm = float(policy.act(obs))
        obs, reward, terminated, truncated, step_info = env.step(mm)
        water, total, days = water + step_info["irrigation_applied_mm"], total + reward, days + 1
        first = first or (mm, step_info["irrigation_applied_mm"], reward, water)
        done = terminated or truncated
    assert (result.days, result.yield_t_ha, result.water_mm) == (days, step_info["yield_t_ha"], water)
    assert result.episode_return == pytest.approx(total, rel=1e-12) and result.reward_unit == "t/ha"
    step = feedback.step
    assert (step.irrigation_requested_mm, step.irrigation_mm, step.reward, feedback.water_mm) == first
    assert step.episode == result.episode == fill(StepResult(), _example("step_result")["message"]).episode + 1
    assert step.header.stamp.sec == ri.sim_time(date.fromisoformat(info["date"]), 1).sec


def test_filler_takes_and_refuses_what_ros2_topic_pub_does():
    from diagnostic_msgs.msg import DiagnosticStatus
    from std_msgs.msg import Float64MultiArray

    with pytest.raises(AttributeError):
        fill(Float64MultiArray(), {"dataa": [1.0]})
    with pytest.raises(TypeError):
        fill(Float64MultiArray(), {"data": "1.0"})
    # a byte field: what `ros2 topic echo` prints ("\x01") is refused as `ros2 topic pub` refuses it; !!binary works
    with pytest.raises(TypeError, match="expected to be a dictionary but is a str"):
        fill(DiagnosticStatus(), yaml.safe_load('level: "\\x01"'))
    assert fill(DiagnosticStatus(), yaml.safe_load("level: !!binary AQ==")).level == DiagnosticStatus.WARN
    # every example's byte fields are written so
    for path in FILES:
        assert '  level: "' not in path.read_text().split("\necho:")[0], path.name
