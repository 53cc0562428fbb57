"""The one reader of every YAML document the project takes from users: bounded in time and memory, and silent
about what a refused file holds.

What a user's YAML may be (each refusal a :class:`YamlInputError`, one line naming the source and, for a problem
inside the document, its line and column; never the document's text nor an expanded value):

- a regular file (a FIFO, a device or a link to ``/dev/zero`` is refused unread: "not a regular file"; it is
  opened non-blocking, so a FIFO without a writer never blocks), of at most ``max_bytes`` bytes (checked
  before reading and by reading at most ``max_bytes + 1``), UTF-8 text;
- one document without anchors or aliases (the "billion laughs" expansion needs them), nested at most
  MAX_DEPTH collections deep, without a duplicate key in any mapping.

Parsing is libyaml's (PyYAML's C parser, as ``CSafeLoader``) with PyYAML's Python composer on top, which checks
each event as it comes: about as fast as ``CSafeLoader`` (the 48 built-in scenarios are read at import), and a
refusal comes before anything large is built. Values are constructed as ``yaml.safe_load`` constructs them,
except that a number with an exponent is a float however it is written (``1e39``, ``3e-4``; YAML 1.1 reads
those as strings).

Package data written by the project itself (the training recipes, which share settings through anchors) may be
read with ``aliases=True``; every other check still applies.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.resolver import Resolver

CONFIG_MAX_BYTES = 64 * 1024  # a configuration file (scenario, sweep, hyperparameters): far more than any needs
MAX_DEPTH = 32  # nested mappings and sequences (the top-level mapping is one); far more than any file needs
_PROBLEM_MAX_CHARS = 120
ANCHORS_REFUSED = "YAML anchors and aliases (& and *) are not allowed"
_QUOTED = re.compile(r"'[^'\n]*'|\"[^\"\n]*\"")

try:  # libyaml's parser where PyYAML was built with it (the pinned wheels are); else PyYAML's own, 10x slower
    from yaml._yaml import CParser as _Parser

    def _init_parser(loader, text: str) -> None:
        _Parser.__init__(loader, text)
except ImportError:  # pragma: no cover - a PyYAML without libyaml
    from yaml.parser import Parser
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Parser(Reader, Scanner, Parser):  # type: ignore[no-redef]
        pass

    def _init_parser(loader, text: str) -> None:
        Reader.__init__(loader, text)
        Scanner.__init__(loader)
        Parser.__init__(loader)


class YamlInputError(ValueError):
    """A YAML source refused: the message names it, where in it (line, column) and what is wrong."""


class YamlSyntaxError(YamlInputError):
    """A source that is not YAML at all (as opposed to YAML refused by a bound or a rule of this module)."""


def _at(source: str, mark) -> str:
    return f"{source}: line {mark.line + 1}, column {mark.column + 1}" if mark is not None else source


class _Resolver(Resolver):
    """YAML 1.1's implicit types (as ``yaml.safe_load``), and a number with an exponent is a float whatever its
    spelling (``1e39``, ``3e-4``, ``1.0e6``: YAML 1.2; YAML 1.1 reads them as strings, so that a schema would
    refuse a number as text)."""


_Resolver.add_implicit_resolver("tag:yaml.org,2002:float",
                                re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789"))


class _CheckedLoader(Composer, _Parser, SafeConstructor, _Resolver):
    """libyaml's events, composed in Python with the checks of the module docstring, constructed safely."""

    allow_aliases = False

    def __init__(self, text: str, source: str) -> None:
        _init_parser(self, text)
        Composer.__init__(self)
        SafeConstructor.__init__(self)
        _Resolver.__init__(self)
        self.source = source
        self.depth = 0

    def _refuse(self, mark, what: str) -> YamlInputError:
        return YamlInputError(f"{_at(self.source, mark)}: {what}")

    def _collection(self, compose, anchor):
        event = self.peek_event()
        if self.depth >= MAX_DEPTH:
            raise self._refuse(event.start_mark, f"nested more than {MAX_DEPTH} levels deep")
        self.depth += 1
        try:
            return compose(anchor)
        finally:
            self.depth -= 1

    # An anchor is refused where it is set; an alias then names no anchor, which PyYAML's composer refuses
    # (:func:`_syntax_error` words it as this refusal).
    def compose_scalar_node(self, anchor):
        if anchor is not None and not self.allow_aliases:
            raise self._refuse(self.peek_event().start_mark, ANCHORS_REFUSED)
        return super().compose_scalar_node(anchor)

    def compose_sequence_node(self, anchor):
        if anchor is not None and not self.allow_aliases:
            raise self._refuse(self.peek_event().start_mark, ANCHORS_REFUSED)
        return self._collection(super().compose_sequence_node, anchor)

    def compose_mapping_node(self, anchor):
        if anchor is not None and not self.allow_aliases:
            raise self._refuse(self.peek_event().start_mark, ANCHORS_REFUSED)
        return self._collection(super().compose_mapping_node, anchor)

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                    seen.add(key)
                except TypeError:  # an unhashable key: the constructor's own error says so
                    continue
                if duplicate:
                    raise self._refuse(key_node.start_mark, "duplicate key (each key may appear once in a mapping)")
        return super().construct_mapping(node, deep)


class _TrustedLoader(_CheckedLoader):
    allow_aliases = True


def _syntax_error(source: str, error: yaml.YAMLError) -> YamlInputError:
    """``error`` in one line naming ``source`` and the place, without quoting the text (quoted parts of PyYAML's
    problem, such as an alias name or a character, become '…')."""
    mark = getattr(error, "problem_mark", None)
    if str(getattr(error, "problem", "")).startswith("found undefined alias"):
        return YamlInputError(f"{_at(source, mark)}: {ANCHORS_REFUSED}")
    problem = _QUOTED.sub("'…'", " ".join(str(getattr(error, "problem", None) or "not valid YAML").split()))
    if len(problem) > _PROBLEM_MAX_CHARS:
        problem = problem[:_PROBLEM_MAX_CHARS - 1] + "…"
    return YamlSyntaxError(f"{_at(source, mark)}: not valid YAML ({problem})")


def loads(text: str, source: str, *, aliases: bool = False) -> Any:
    """The one YAML document of ``text`` (None for an empty one), checked as the module docstring says;
    ``source`` names it in a refusal (a path, ``--hyperparams net_arch``). ``aliases=True``: for the project's
    own files only."""
    loader = (_TrustedLoader if aliases else _CheckedLoader)(text, source)
    try:
        return loader.get_single_data()
    except YamlInputError:
        raise
    except yaml.YAMLError as error:
        raise _syntax_error(source, error) from None
    except RecursionError:  # pragma: no cover - MAX_DEPTH keeps the recursion far below the limit
        raise YamlInputError(f"{source}: nested too deep") from None
    except ValueError:  # Python's int() refuses integers of more than 4,300 digits
        raise YamlInputError(f"{source}: a number too long to read") from None
    finally:
        loader.dispose()


def read_text(path: str | os.PathLike, max_bytes: int = CONFIG_MAX_BYTES, source: str | None = None) -> str:
    """The UTF-8 text of the regular file ``path`` of at most ``max_bytes`` bytes; YamlInputError (naming
    ``source``, default the path) for anything else, without reading more than ``max_bytes + 1`` bytes and
    without blocking on a FIFO."""
    source = str(path) if source is None else source
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
    try:
        descriptor = os.open(path, flags)
    except FileNotFoundError:
        raise YamlInputError(f"{source}: no such file") from None
    except OSError as error:
        raise YamlInputError(f"{source}: cannot be opened ({error.strerror or type(error).__name__})") from None
    try:
        info = os.fstat(descriptor)
        if not stat.S_ISREG(info.st_mode):
            kind = "a directory, " if stat.S_ISDIR(info.st_mode) else ""
            raise YamlInputError(f"{source}: {kind}not a regular file")
        if info.st_size > max_bytes:
            raise YamlInputError(f"{source}: {info.st_size:,} bytes, more than the {max_bytes:,} allowed")
        os.set_blocking(descriptor, True)
        chunks, size = [], 0
        while size <= max_bytes:
            chunk = os.read(descriptor, max_bytes + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as error:
        raise YamlInputError(f"{source}: cannot be read ({error.strerror or type(error).__name__})") from None
    finally:
        os.close(descriptor)
    if size > max_bytes:  # it grew while being read
        raise YamlInputError(f"{source}: more than the {max_bytes:,} bytes allowed")
    try:
        return b"".join(chunks).decode("utf-8")
    except UnicodeDecodeError as error:
        raise YamlInputError(f"{source}: not UTF-8 text (byte {error.start + 1})") from None


def read_yaml(path: str | os.PathLike, *, max_bytes: int = CONFIG_MAX_BYTES, source: str | None = None,
              aliases: bool = False) -> Any:
    """The YAML document of the file ``path`` (:func:`read_text`, then :func:`loads`); YamlInputError (a
    ValueError) naming ``source`` (default: the path) for every refusal."""
    source = str(Path(path)) if source is None else source
    return loads(read_text(path, max_bytes, source), source, aliases=aliases)
