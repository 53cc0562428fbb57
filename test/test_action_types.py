"""Actions of the irrigation environments: numbers only. ``float()`` would quietly take a string, a bool, a
Decimal or a Fraction; the environments refuse them with a TypeError instead."""

from decimal import Decimal
from fractions import Fraction

import numpy as np
import pytest

from crop_sim_ros.task import IrrigationEnv, IrrigationVectorEnv

NON_NUMERIC = {
    "str": "5",
    "bool": True,
    "numpy bool": np.bool_(True),
    "Decimal": Decimal("5"),
    "Fraction": Fraction(5, 1),
    "object array": np.array([Decimal("5")], dtype=object),
    "str array": np.array(["5"]),
    "bool array": np.array([True]),
    "list of str": ["5"],
    "list of Decimal": [Decimal("5")],
    "None": None,
}


@pytest.fixture(scope="module")
def env():
    return IrrigationEnv()


@pytest.mark.parametrize("action", NON_NUMERIC.values(), ids=NON_NUMERIC.keys())
def test_single_env_refuses_non_numeric_actions(env, action):
    env.reset(seed=0)
    with pytest.raises(TypeError, match="number of mm"):
        env.step(action)
    # refused before anything happened: the next valid step is still day 0 -> 1
    _, _, _, _, info = env.step(np.array([5.0], np.float32))
    assert info["day"] == 1 and info["irrigation_applied_mm"] == 5.0


NUMERIC = {"float": 7.5, "int": 7, "numpy float32": np.float32(7.5), "numpy int64": np.int64(7),
           "float32 array": np.array([7.5], np.float32), "0-d array": np.array(7.5), "int array": np.array([7]),
           "list": [7.5], "tuple": (7,)}


@pytest.mark.parametrize("action", NUMERIC.values(), ids=NUMERIC.keys())
def test_single_env_takes_every_real_number_form(env, action):
    env.reset(seed=3)
    _, _, _, _, info = env.step(action)
    expected = 7.5 if "7.5" in repr(action) else 7.0
    assert info["irrigation_requested_mm"] == expected and type(info["irrigation_requested_mm"]) is float


@pytest.mark.parametrize("action", [[1.0, 2.0], np.zeros(2), np.zeros((1, 2))])
def test_single_env_refuses_more_than_one_amount(env, action):
    env.reset(seed=0)
    with pytest.raises(ValueError, match="one irrigation amount"):
        env.step(action)


@pytest.mark.parametrize("actions", [np.array(["5", "5"]), np.array([True, False]),
                                     np.array([Decimal(5), Decimal(5)], dtype=object), ["5", "5"],
                                     [Fraction(1), Fraction(2)]],
                         ids=["str", "bool", "Decimal objects", "list of str", "list of Fraction"])
def test_vector_env_refuses_non_numeric_actions(actions):
    vec = IrrigationVectorEnv(num_envs=2)
    vec.reset(seed=0)
    with pytest.raises(TypeError, match="numbers of mm"):
        vec.step(actions)
    _, _, _, _, infos = vec.step(np.array([[1.0], [2.0]], np.float32))
    assert infos["day"].tolist() == [1, 1] and infos["irrigation_applied_mm"].tolist() == [1.0, 2.0]
