"""Strict pydantic schemas of configuration files, derived from the frozen dataclasses they describe.

A file's shape is declared once, by the dataclasses it becomes (their field names, types and which fields have
defaults); :func:`dataclass_model` turns a dataclass into a strict pydantic model of what a YAML file may hold
for it, and :class:`Rules` adds what a type alone does not say: the range of a number, the choices of a
string, fields a file writes differently. The model checks types (no bool or string where a number belongs,
an integer accepted where a float is), finite numbers in their ranges, required and unknown keys; a
:class:`ValidationError` becomes one line listing every problem with its path (:func:`problems`), never quoting
a value. pydantic is imported when a schema is first built, not when this module is.

Type mapping: ``float`` -> a finite number (int or float, not bool) in its range, as float; ``int`` -> an
integer (not bool); ``bool``, ``str`` (at most MAX_TEXT_CHARS; choices: one of them); ``date`` -> a YAML date
or an ISO ``YYYY-MM-DD`` string; ``tuple[X, ...]`` -> a list of X; ``tuple[X, X]`` -> a list of two X;
:class:`~crop_sim_ros.task.terms.Range` -> a number or a ``[low, high]`` list of numbers in its range; a
dataclass -> a mapping of its fields (recursively); ``X | None`` -> X or null.
"""

from __future__ import annotations

import functools
import math
import re
import types
import typing
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from datetime import date
from typing import Any

from .terms import Range

MAX_TEXT_CHARS = 1000  # any string of a configuration file (names, paths, descriptions)
MAX_LISTED_PROBLEMS = 8
_KEY_MAX_CHARS = 40


@dataclass(frozen=True, eq=False)  # hashed by identity: a schema is built once per Rules
class Rules:
    """What the dataclasses' types do not say, by dotted field path (``limits.quota_mm``; ``noise.*``: every
    field of ``noise``; a list's items share their list's path): ``bounds`` (low, high; None: unbounded) of
    numbers, ``choices`` of strings, ``extra`` fields (name -> Python type) a file may hold beside the
    dataclass's own, ``exclude`` fields a file may not set."""

    bounds: dict[str, tuple[float | None, float | None]] = field(default_factory=dict)
    choices: dict[str, tuple[str, ...]] = field(default_factory=dict)
    extra: dict[str, dict[str, Any]] = field(default_factory=dict)
    exclude: frozenset[str] = frozenset()

    def bound(self, path: str) -> tuple[float | None, float | None]:
        parent = path.rpartition(".")[0]
        return self.bounds.get(path, self.bounds.get(f"{parent}.*" if parent else "*", (None, None)))


def _pydantic():
    import pydantic  # noqa: PLC0415 - a schema is built on the first file read, not at import
    return pydantic


def _iso_date(value: Any) -> Any:
    """A YAML date as it is, an ISO date string as a date (anything else is left to the strict date check)."""
    if isinstance(value, str):
        try:
            return date.fromisoformat(value)
        except ValueError:
            from pydantic_core import PydanticCustomError  # noqa: PLC0415
            raise PydanticCustomError("date", "expected a date YYYY-MM-DD") from None
    return value


_NAME = re.compile(r"[\w.+-]{1,40}")  # a name-like string, the only kind a message may quote


def shown(value: Any) -> str:
    """A refused YAML value in a message: a number or true/false as written, a short name-like string quoted,
    else only its kind (never text of the file beyond that)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value) if abs(value) < 10**15 else "a very large number"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return repr(value) if _NAME.fullmatch(value) else "a string"
    for kind, words in ((list, "a list"), (dict, "a mapping"), (type(None), "null"), (date, "a date")):
        if isinstance(value, kind):
            return words
    return "a value"


def _in(value: Any, whole: bool, low: float | None, high: float | None) -> bool:
    """Whether ``value`` is a number of the kind asked (an int for a float too, never a bool), finite, in range."""
    kinds = int if whole else (int, float)
    return (isinstance(value, kinds) and not isinstance(value, bool) and (whole or math.isfinite(value))
            and (low is None or value >= low) and (high is None or value <= high))


def _custom_error(kind: str, message: str):
    from pydantic_core import PydanticCustomError  # noqa: PLC0415
    return PydanticCustomError(kind, message.replace("{", "{{").replace("}", "}}"))


def _number_validator(whole: bool, low: float | None, high: float | None):
    """An integer (``whole``) or a finite number in [low, high], as int or float."""
    if whole:
        expected = f"a whole number in {'' if low is None else f'{low:g}'}..{'' if high is None else f'{high:g}'}"
    else:
        expected = f"a finite number in [{-math.inf if low is None else low:g}, {math.inf if high is None else high:g}]"

    def check(value: Any) -> Any:
        if not _in(value, whole, low, high):
            raise _custom_error("number", f"{shown(value)} is not {expected}")
        return int(value) if whole else float(value)
    return check


def _range_validator(low: float | None, high: float | None):
    """A number or a [low, high] pair of numbers, each finite and in [low, high] (a Range's YAML)."""
    expected = f"a finite number in [{-math.inf if low is None else low:g}, {math.inf if high is None else high:g}]"

    def check(value: Any) -> Any:
        if isinstance(value, list) and len(value) == 2:
            for item in value:
                if not _in(item, False, low, high):
                    raise _custom_error("range", f"{shown(item)} in [low, high] is not {expected}")
            return [float(v) for v in value]
        if not _in(value, False, low, high):
            raise _custom_error("range", f"{shown(value)} is not {expected}, nor a [low, high] pair of them")
        return float(value)
    return check


def _pair_validator(whole: bool, low: float | None, high: float | None):
    """A [least, most] list of two numbers, each as :func:`_number_validator` checks it (ClimateSpread's ranges)."""
    one = _number_validator(whole, low, high)

    def check(value: Any) -> Any:
        if not (isinstance(value, list) and len(value) == 2):
            raise _custom_error("pair", f"expected [least, most], got {shown(value)}")
        return [one(item) for item in value]
    return check


def _choice_validator(choices: tuple[str, ...]):
    """One of ``choices`` (strings)."""
    def check(value: Any) -> Any:
        if not (isinstance(value, str) and value in choices):
            raise _custom_error("choice", f"{shown(value)} is not one of {', '.join(c or repr(c) for c in choices)}")
        return value
    return check


def _annotation(tp: Any, path: str, rules: Rules) -> Any:
    """The pydantic annotation of a YAML value that becomes a ``tp`` at ``path``."""
    pydantic = _pydantic()
    Annotated, Field = typing.Annotated, pydantic.Field
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        present = [a for a in args if a is not type(None)]
        inner = _annotation(present[0] if len(present) == 1 else typing.Union[tuple(present)], path, rules)
        return typing.Optional[inner] if len(present) < len(args) else inner
    if tp is bool:
        return bool
    if tp in (int, float):
        return Annotated[Any, pydantic.PlainValidator(_number_validator(tp is int, *rules.bound(path)))]
    if tp is str:
        choices = rules.choices.get(path)
        return (Annotated[Any, pydantic.PlainValidator(_choice_validator(choices))] if choices
                else Annotated[str, Field(max_length=MAX_TEXT_CHARS)])
    if tp is date:
        return Annotated[date, pydantic.BeforeValidator(_iso_date)]
    if tp is Range:
        return Annotated[Any, pydantic.PlainValidator(_range_validator(*rules.bound(path)))]
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return list[_annotation(args[0], path, rules)]
        if len(args) == 2 and args[0] == args[1] and args[0] in (int, float):
            return Annotated[Any, pydantic.PlainValidator(_pair_validator(args[0] is int, *rules.bound(path)))]
    if is_dataclass(tp):
        return dataclass_model(tp, rules, path)
    raise TypeError(f"{path}: no schema for the type {tp!r}")  # a field of a new type: say what it reads as


@functools.lru_cache(maxsize=None)
def dataclass_model(cls: type, rules: Rules, path: str = ""):
    """The strict pydantic model of what a file may hold for the dataclass ``cls`` at ``path`` (see the module
    docstring): a field with a default may be left out; unknown keys are refused."""
    pydantic = _pydantic()
    hints = typing.get_type_hints(cls)
    definitions = {}
    for item in fields(cls):
        where = f"{path}.{item.name}" if path else item.name
        if where in rules.exclude:
            continue
        required = item.default is MISSING and item.default_factory is MISSING
        definitions[item.name] = (_annotation(hints[item.name], where, rules), ... if required else None)
    for name, tp in rules.extra.get(path, {}).items():
        definitions[name] = (_annotation(tp, f"{path}.{name}" if path else name, rules), None)
    config = pydantic.ConfigDict(strict=True, extra="forbid", frozen=True)
    return pydantic.create_model(f"{cls.__name__}File", __config__=config, **definitions)


def _key(part: Any) -> str:
    text = str(part)
    return text if len(text) <= _KEY_MAX_CHARS else text[:_KEY_MAX_CHARS - 1] + "…"


def _fields_at(model, loc: tuple) -> list[str]:
    """The field names of the (nested) model at ``loc`` (the mapping an unknown key was found in)."""
    for part in loc:
        if isinstance(part, int) or model is None:
            continue
        info = model.model_fields.get(part)
        model = None
        for candidate in _models_in(info.annotation if info else None):
            model = candidate
    return sorted(model.model_fields) if model is not None else []


def _models_in(annotation) -> list:
    """The pydantic models an annotation holds (through Optional, list and Annotated)."""
    if isinstance(annotation, type) and hasattr(annotation, "model_fields"):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models_in(arg)]


def problems(error, root: str, model=None) -> str:
    """A pydantic ValidationError as one line: ``root.path.to.field: what`` for every problem (at most
    MAX_LISTED_PROBLEMS, then how many more), without the values."""
    messages = {"extra_forbidden": "unknown field", "missing": "missing (required)", "model_type": "expected a mapping",
                "dict_type": "expected a mapping", "list_type": "expected a list", "string_type": "expected text",
                "bool_type": "expected true or false", "date_type": "expected a date YYYY-MM-DD"}
    found = []
    for item in error.errors(include_url=False, include_input=False):
        where = root
        for part in item["loc"]:
            if isinstance(part, int):
                where += f"[{part}]"
            elif not str(part).startswith("function-"):
                where += f".{_key(part)}" if where else _key(part)
        message = messages.get(item["type"], item["msg"])
        if item["type"] == "extra_forbidden" and model is not None:
            message += f" (known: {', '.join(_fields_at(model, item['loc'][:-1]))})"
        line = f"{where or '(top level)'}: {message}"
        if line not in found:
            found.append(line)
    more = f"; and {len(found) - MAX_LISTED_PROBLEMS} more" if len(found) > MAX_LISTED_PROBLEMS else ""
    return "; ".join(found[:MAX_LISTED_PROBLEMS]) + more


def validated(cls: type, rules: Rules, values: Any, root: str = "") -> dict:
    """``values`` (a YAML mapping for ``cls``) checked by its schema: the fields it sets, numbers as the types
    they become (an integer latitude as float, a list as list). ValueError listing every problem."""
    model = dataclass_model(cls, rules)
    pydantic = _pydantic()
    if not isinstance(values, dict):
        raise ValueError(f"{root or 'the file'}: expected a mapping of fields, got {shown(values)}")
    try:
        checked = model.model_validate(values)
    except pydantic.ValidationError as error:
        raise ValueError(problems(error, root, model)) from None
    return _dump(checked)


def _dump(model) -> dict:
    """The fields a model was given, nested models as dicts (dates, lists and numbers as validated)."""
    return {name: _dump(value) if hasattr(value, "model_fields_set") else
            [_dump(v) if hasattr(v, "model_fields_set") else v for v in value] if isinstance(value, list) else value
            for name, value in ((name, getattr(model, name)) for name in model.model_fields_set)}
