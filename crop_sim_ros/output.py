"""Result files written whole or not at all, and output folders checked before any work.

Every result file a command writes (tables, summaries, plots, models) goes through :func:`replace_atomically`:
the content is written to a temporary file in the same folder (``.<name>.<random>.tmp<suffix>``), flushed and
fsynced, then renamed over ``path`` (``os.replace``, atomic on POSIX). A reader sees the old file or the new one,
never a torn one: a full disk, a file-size limit or a crash while writing leaves the previous file intact. A
failed write removes its temporary file and raises :class:`WriteError` (a :class:`~crop_sim_ros.usage.UsageError`:
the command ends in one line naming the path, exit status 2).

:func:`check_output_directory` says, before a command does any work, whether ``--out`` can be a folder of results
(not a file, not under a file, not in /proc, /sys or /dev, writable); :func:`output_directory` also creates it.
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

from .usage import UsageError, one_line

# Kernel file systems: a path there is never a place for results (writing may even act on the system).
SYSTEM_ROOTS = (Path("/proc"), Path("/sys"), Path("/dev"))


class WriteError(UsageError):
    """A result file could not be written (full disk, no permission, ...); the previous file is unchanged."""


def _fsync_directory(directory: Path) -> None:
    """Make the rename itself durable (best effort: some file systems refuse to fsync a folder)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _mode_of(path: Path) -> int:
    """The permissions the result file gets: the replaced file's, else those of a new file (0o666 less the umask;
    mkstemp's own are 0o600)."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        mask = os.umask(0o022)
        os.umask(mask)
        return 0o666 & ~mask


def replace_atomically(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(temporary)`` to write the content to a temporary path in ``path``'s folder (its name ends
    in ``path``'s suffix, so matplotlib and Stable-Baselines3 keep the format), fsync it and rename it over
    ``path``. WriteError naming ``path`` if anything fails (the temporary file removed, ``path`` unchanged)."""
    path = Path(path)
    directory = path.parent
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=directory)
    except OSError as error:
        raise WriteError(f"cannot write {path}: {one_line(error)}") from None
    os.close(fd)
    temporary = Path(name)
    try:
        write(temporary)
        os.chmod(temporary, _mode_of(path))
        with open(temporary, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(temporary, path)
    except BaseException as error:
        try:
            temporary.unlink()
        except OSError:
            pass
        if isinstance(error, OSError):
            raise WriteError(f"cannot write {path}: {one_line(error)} (any previous {path.name} is unchanged)") \
                from None
        raise
    _fsync_directory(directory)
    return path


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """``data`` as the whole content of ``path``, atomically (see :func:`replace_atomically`)."""

    def write(temporary: Path) -> None:
        with open(temporary, "wb") as handle:
            handle.write(data)
            handle.flush()

    return replace_atomically(path, write)


def write_text_atomic(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """``text`` as the whole content of ``path`` (no newline translation), atomically."""
    return write_bytes_atomic(path, text.encode(encoding))


def write_json_atomic(path: str | Path, value, indent: int | None = 1, **dumps_options) -> Path:
    """``value`` as JSON (``json.dumps(value, indent=indent, **dumps_options)`` and a final newline), atomically;
    the text is made before anything is written, so a value JSON refuses leaves ``path`` untouched."""
    return write_text_atomic(path, json.dumps(value, indent=indent, **dumps_options) + "\n")


def write_csv_atomic(path: str | Path, header: Sequence[str], rows: Iterable[Mapping | Sequence]) -> Path:
    """A CSV file of ``header`` and ``rows`` (mappings by column name, or sequences in ``header``'s order),
    atomically; lines end in ``\\r\\n`` as the csv module writes them."""
    buffer = io.StringIO(newline="")
    rows = iter(rows)
    first = next(rows, None)
    if isinstance(first, Mapping):
        writer = csv.DictWriter(buffer, fieldnames=list(header))
        writer.writeheader()
    else:
        writer = csv.writer(buffer)
        writer.writerow(header)
    if first is not None:
        writer.writerow(first)
        writer.writerows(rows)
    return write_text_atomic(path, buffer.getvalue())


def save_figure_atomic(figure, path: str | Path, **savefig_options) -> Path:
    """``figure.savefig`` to a temporary name in the format of ``path``'s suffix, then renamed over ``path``."""
    path = Path(path)
    fmt = path.suffix.lstrip(".") or None
    return replace_atomically(path, lambda temporary: figure.savefig(temporary, format=fmt, **savefig_options))


def _in_system_tree(path: Path) -> bool:
    return any(path == root or root in path.parents for root in SYSTEM_ROOTS)


def check_output_directory(path: str | Path, option: str = "--out") -> Path:
    """``path`` (absolute) if it can be a folder of results, creating nothing: UsageError, one line naming
    ``option``, if it is a file, lies under a file, lies in /proc, /sys or /dev, or its nearest existing folder is
    not writable."""
    out = Path(os.path.abspath(path))
    if _in_system_tree(Path(os.path.realpath(out))) or _in_system_tree(out):
        raise UsageError(f"{option}: {path} is in a kernel file system (/proc, /sys, /dev), not a place for results")
    if out.exists() and not out.is_dir():
        raise UsageError(f"{option}: {path} is a file, not a folder")
    existing = out
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise UsageError(f"{option}: {path} lies under {existing}, which is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UsageError(f"{option}: cannot write in {existing} (read-only or no permission)")
    return out


def output_directory(path: str | Path, option: str = "--out") -> Path:
    """:func:`check_output_directory`, then the folder created (with its parents) if missing; ``path`` as given
    (relative stays relative)."""
    check_output_directory(path, option)
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UsageError(f"{option}: cannot create {path}: {one_line(error)}") from None
    return out


def check_output_file(path: str | Path, option: str) -> Path:
    """``path`` if a result file can be written there (its folder as :func:`check_output_directory` checks it,
    and ``path`` itself not a folder); creates nothing."""
    path = Path(path)
    if path.is_dir():
        raise UsageError(f"{option}: {path} is a folder, not a file")
    check_output_directory(path.parent if str(path.parent) else ".", option)
    return path
