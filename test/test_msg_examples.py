"""msg_examples/: every topic and service of the simulator has an example, each example fills the real message
type as ``ros2 topic pub`` / ``ros2 service call`` would (rosidl_runtime_py's ``set_message_fields`` on
``yaml.safe_load``'s values; where rosidl_runtime_py is not installed, a port of that function that takes
and refuses the same values: a byte field such as DiagnosticStatus.level takes ``!!binary``, not the ``"\x01"``
that ``ros2 topic echo`` prints), matches what the node publishes (labels, sizes, types), and the examples
agree with each other (the command of irrigation.yaml is for the day the reset of reset.yaml starts on, and
step.yaml's answer is the next day)."""

from __future__ import annotations

import array
import copy
import importlib
import json
import shlex
from datetime import date, timedelta
from pathlib import Path

import numpy as np
import pytest
import yaml


from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from crop_sim_ros import ros_interface as ri  # noqa: E402
from crop_sim_ros.task import IrrigationEnv  # noqa: E402
from crop_sim_ros.task.layout import EXTENDED, PAPER  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "msg_examples"
FILES = sorted(EXAMPLES.glob("*.yaml"))

# every name the simulator serves -> (kind, interface type, the labels it uses, if any)
INTERFACE = {
    "/crop_sim/observation": ("topic", "std_msgs/msg/Float32MultiArray", ri.OBSERVATION_LABELS),
    "/crop_sim/biomass": ("topic", "std_msgs/msg/Float64MultiArray", ri.BIOMASS_READING.labels),
    "/crop_sim/paw": ("topic", "std_msgs/msg/Float64MultiArray", ri.PAW_READING.labels),
    "/crop_sim/weather/today": ("topic", "std_msgs/msg/Float64MultiArray", ri.WEATHER_TODAY.labels),
    "/crop_sim/weather/forecast": ("topic", "std_msgs/msg/Float64MultiArray", ri.WEATHER_FORECAST.labels),
    "/crop_sim/step_result": ("topic", "std_msgs/msg/Float64MultiArray", ri.STEP_RESULT.labels),
    "/crop_sim/farm_terms": ("topic", "std_msgs/msg/Float64MultiArray", ri.FARM_TERMS.labels),
    "/crop_sim/irrigation": ("topic", "std_msgs/msg/Float64MultiArray", ri.IRRIGATION.labels[:2]),
    "/crop_sim/irrigation_step": ("topic", "std_msgs/msg/Float64MultiArray", ri.IRRIGATION.labels),
    "/crop_sim/irrigation_status": ("topic", "diagnostic_msgs/msg/DiagnosticStatus", None),
    "/diagnostics": ("topic", "diagnostic_msgs/msg/DiagnosticArray", None),
    "/clock": ("topic", "rosgraph_msgs/msg/Clock", None),
    "/crop_sim/step": ("service", "std_srvs/srv/Trigger", None),
    "/crop_sim/reset": ("service", "std_srvs/srv/Trigger", None),
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


def test_every_topic_and_service_has_one_example():
    names = [yaml.safe_load(path.read_text())["name"] for path in FILES]
    assert sorted(names) == sorted(INTERFACE), "one msg_examples/*.yaml per topic and service"


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_example_fills_the_real_type(path):
    example = yaml.safe_load(path.read_text())
    kind, type_name, labels = INTERFACE[example["name"]]
    assert example["kind"] == kind and example["type"] == type_name
    cls = interface_class(type_name)
    if kind == "topic":
        messages = [example["message"]] + [example[k] for k in ("message_with_episode", "rejected_message") if k in example]
        for values in messages:
            message = fill(cls(), values)
            again = deserialize_message(serialize_message(message), cls)
            assert plain(again) == plain(message)
        first = fill(cls(), example["message"])
        # what `ros2 topic echo` shows is the same message
        assert yaml.safe_load(example["echo"].removesuffix("---\n")) == plain(first)
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
        elif type_name.endswith("DiagnosticStatus"):
            status = ri.status_values(first)
            assert status["accepted"] and status["irrigation_mm"] == 12.5
        if example["command"].startswith("ros2 topic pub"):  # the command publishes the example as it stands
            *_, topic, type_arg, payload = shlex.split(example["command"])
            assert (topic, type_arg) == (example["name"], type_name)
            assert plain(fill(cls(), yaml.safe_load(payload), "command")) == plain(first)
        if example["name"] in ("/crop_sim/irrigation", "/crop_sim/irrigation_step"):
            assert first.data[0] == int(first.data[0]) and 0 <= first.data[1] <= 100
            assert example["command"].startswith("ros2 topic pub")
    else:
        request = fill(cls.Request(), example["request"], "request")
        response = fill(cls.Response(), example["response"], "response")
        assert isinstance(request, cls.Request)
        summary = json.loads(response.message)
        assert summary["day"] >= 0 and summary["episode"] >= 1
        observation = np.asarray(summary["observation"], dtype=np.float32)
        assert observation.shape == (PAPER.size,) and observation[ri.OBS_DAY] == summary["day"]
        assert np.array_equal(observation.astype(np.float64), summary["observation"]), "exact float32 values"
        if "failure_response" in example:
            failure = fill(cls.Response(), example["failure_response"], "failure_response")
            assert not failure.success and "error" in json.loads(failure.message)


def test_family_examples_are_a_benton_quota_season():
    """The family observation and the farm terms examples: benton-quota, seed 0, day 1 after 20 mm (the
    pivot's 8 mm applied), as the offline environment gives them; labels from the extended layout."""
    env = IrrigationEnv("benton-quota")
    env.reset(seed=0)
    obs, _, _, _, info = env.step(20.0)
    family = fill(interface_class("std_msgs/msg/Float32MultiArray")(),
                  yaml.safe_load((EXAMPLES / "observation.yaml").read_text())["family_message"])
    assert family.layout.dim[0].label == ",".join(EXTENDED.labels) and family.layout.dim[0].size == 29
    assert ri.observation_from_message(family, EXTENDED).tobytes() == obs.tobytes()
    terms = yaml.safe_load((EXAMPLES / "farm_terms.yaml").read_text())["message"]["data"]
    assert terms[1:] == [info["yield_value_per_t"] * env.scenario.economics.tuber_dry_matter_fraction,
                         info["water_cost_per_mm"], 0.0, info["quota_mm"], 8.0]
    assert info["irrigation_applied_mm"] == 8.0 and obs[EXTENDED.index("irrigation_yesterday_mm")] == 8.0


def _example(name: str) -> dict:
    return yaml.safe_load((EXAMPLES / f"{name}.yaml").read_text())


def test_the_examples_tell_one_story_reset_command_status_step_clock():
    """reset.yaml starts episode E on day 0; irrigation.yaml and irrigation_step.yaml command that day (a
    command for day 1 right after a reset is refused: "day 1 is in the future"); irrigation_status.yaml accepts
    it as command #k and refuses one for the future; step.yaml applies #k and answers day 1, one day after the
    reset's date, which /clock (clock.yaml) then shows."""
    reset = json.loads(_example("reset")["response"]["message"])
    step = json.loads(_example("step")["response"]["message"])
    episode, day = reset["episode"], reset["day"]
    assert day == 0
    command = _example("irrigation")
    assert command["message"]["data"] == [day, 12.5]
    assert command["message_with_episode"]["data"] == [day, 12.5, episode]
    assert _example("irrigation_step")["message"]["data"] == [day, 12.5, episode]
    status_example = _example("irrigation_status")
    accepted = ri.status_values(fill(interface_class("diagnostic_msgs/msg/DiagnosticStatus")(),
                                     status_example["message"]))
    assert accepted["accepted"] and accepted["day"] == accepted["current_day"] == day
    assert accepted["message"] == f"accepted 12.5 mm for day {day} (episode {episode})"
    refused = ri.status_values(fill(interface_class("diagnostic_msgs/msg/DiagnosticStatus")(),
                                    status_example["rejected_message"]))
    assert not refused["accepted"] and refused["current_day"] == day and refused["day"] == day + 1
    assert refused["message"] == f"rejected: day {day + 1} is in the future: the current day is {day}"
    assert refused["sequence"] == accepted["sequence"] + 1
    assert (step["episode"], step["day"], step["irrigation_mm"]) == (episode, day + 1, 12.5)
    assert step["command_sequence"] == accepted["sequence"]
    stepped = date.fromisoformat(reset["date"]) + timedelta(days=1)
    assert step["date"] == stepped.isoformat()
    assert _example("clock")["message"]["clock"]["sec"] == ri.sim_time(date.fromisoformat(reset["date"]), 1).sec


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
