"""msg_examples/: every topic and service of the simulator has an example, and each example fills the real
message type (rosidl_runtime_py is not installable here, so a small YAML -> message filler does what
``ros2 topic pub`` does) and matches what the node publishes (labels, sizes, types)."""

from __future__ import annotations

import importlib
import json
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
    "/crop_sim/status": ("topic", "diagnostic_msgs/msg/DiagnosticStatus", None),
    "/clock": ("topic", "rosgraph_msgs/msg/Clock", None),
    "/crop_sim/step": ("service", "std_srvs/srv/Trigger", None),
    "/crop_sim/reset": ("service", "std_srvs/srv/Trigger", None),
}

_PRIMITIVES = {"double": float, "float": float, "string": str, "boolean": bool,
               **{t: int for t in ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")}}


def interface_class(name: str):
    """'std_msgs/msg/Float64MultiArray' -> the Python class."""
    package, kind, type_name = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), type_name)


def _value(field_type: str, value, where: str):
    if field_type.startswith("sequence<") or field_type.endswith("]"):
        inner = field_type[len("sequence<"):-1] if field_type.startswith("sequence<") else field_type.split("[")[0]
        if not isinstance(value, list):
            raise TypeError(f"{where}: expected a list for {field_type}, got {value!r}")
        return [_value(inner, item, f"{where}[{i}]") for i, item in enumerate(value)]
    if field_type == "octet":  # a byte: YAML "\0" (as ros2 topic echo prints it) or an integer
        if isinstance(value, str) and len(value) == 1:
            return bytes([ord(value)])
        if isinstance(value, int) and 0 <= value < 256:
            return bytes([value])
        raise TypeError(f"{where}: expected a byte, got {value!r}")
    if field_type in _PRIMITIVES:
        kind = _PRIMITIVES[field_type]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise TypeError(f"{where}: expected {field_type}, got {value!r}")
        return value
    if "/" in field_type:  # a nested message, e.g. 'std_msgs/MultiArrayLayout'
        package, type_name = field_type.split("/")
        return fill(interface_class(f"{package}/msg/{type_name}")(), value, where)
    raise TypeError(f"{where}: unsupported field type {field_type}")


def fill(message, values: dict, where: str = "message"):
    """Set ``message``'s fields from a YAML mapping, as ``ros2 topic pub`` does; unknown fields raise."""
    if not isinstance(values, dict):
        raise TypeError(f"{where}: expected a mapping, got {values!r}")
    types = message.get_fields_and_field_types()
    for key, value in values.items():
        if key not in types:
            raise KeyError(f"{where}: {type(message).__name__} has no field {key!r} (fields: {', '.join(types)})")
        setattr(message, key, _value(types[key], value, f"{where}.{key}"))
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
        if example["name"] == "/crop_sim/status":
            status = ri.node_status_values(first)
            assert set(ri.NODE_STATUS_KEYS) <= {kv.key for kv in first.values}
            assert status["level"] == 1 and status["days_without_command"] == status["day"] - 1
        elif type_name.endswith("DiagnosticStatus"):
            status = ri.status_values(first)
            assert status["accepted"] and status["day"] == 1.0 and status["irrigation_mm"] == 12.5
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


def test_filler_rejects_unknown_fields_and_bad_types():
    from std_msgs.msg import Float64MultiArray

    with pytest.raises(KeyError):
        fill(Float64MultiArray(), {"dataa": [1.0]})
    with pytest.raises(TypeError):
        fill(Float64MultiArray(), {"data": "1.0"})
