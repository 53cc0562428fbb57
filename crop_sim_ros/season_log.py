"""The simulator node's season log: one CSV row per simulated day, appended, never left with a torn row.

- Each row is one ``os.write`` of the whole line straight to the file (no buffer in the process), so a node
  that is killed loses nothing it has logged.
- If a write fails (a full disk, a file-size limit), the file is cut back to its last whole row and the error
  is raised: the caller reports the lost row, and the next row starts on a line of its own.
- Opening an existing log checks its header and removes a torn last line (a row cut short by a crash, or by
  a writer without the rule above) before the first append; :attr:`SeasonLog.repaired_bytes` says how much.

Columns (:data:`LOG_COLUMNS`): when and by which run, the scenario and season, the observation the day started
with (every column of the family's layout, by name: a paper task leaves the 9 extra ones empty), the command,
the irrigation requested and applied, the reward and its unit, the day's water fluxes, the true state at its
end and the season's farm terms (``term_*``, as on the simulator's ``~/farm_terms``).
Rows end with CRLF, the csv module's default, as logs of earlier versions do.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from .task.layout import EXTENDED

OBS_COLUMNS = tuple(f"obs_{name}" for name in EXTENDED.names)  # EXTENDED starts with the paper's 20
TERM_COLUMNS = ("term_tuber_price_usd_per_t", "term_water_cost_usd_per_mm", "term_event_cost_usd", "term_quota_mm",
                "term_capacity_mm_per_day")
LOG_COLUMNS = (("wall_time_utc", "run_id", "episode", "scenario", "seed", "weather_season", "day", "date")
               + OBS_COLUMNS
               + ("command_sequence", "irrigation_requested_mm", "irrigation_mm", "reward", "reward_unit",
                  "episode_return", "terminated", "truncated",
                  "rain_mm", "runoff_mm", "drainage_mm", "transpiration_mm", "et0_mm", "arid",
                  "end_true_biomass_t_ha", "end_true_paw_mm", "end_thermal_time_degc_d", "end_fsolar",
                  "end_yield_t_ha", "end_mature", "potential_yield_t_ha", "normalized_return")
               + TERM_COLUMNS)
HEADER_LINE = ",".join(LOG_COLUMNS)
_HEADER_READ_BYTES = 64 * 1024  # more than the header line: a longer first line is not our header
_TAIL_READ_BYTES = 64 * 1024  # read from the end at a time, looking for the last line break


class LogPathError(ValueError):
    """The log path cannot be used (a directory, not writable, a file with other columns, ...)."""


def _first_line(path: Path) -> bytes:
    with open(path, "rb") as existing:
        return existing.read(_HEADER_READ_BYTES).split(b"\n", 1)[0]


def log_path_problem(path: Path) -> str | None:
    """Why ``path`` cannot be the season log, or None. Creates nothing (a parameter is checked when set)."""
    path = Path(path).expanduser()
    if path.is_dir():
        return f"log_path: {path} is a directory"
    if path.exists():
        if not path.is_file():
            return f"log_path: {path} is not a regular file"
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_APPEND))
            first = _first_line(path)
        except OSError as error:
            return f"log_path: {path} cannot be appended to ({error.strerror})"
        line = first.rstrip(b"\r").decode("utf-8", errors="replace")
        complete = first != b"" and len(first) < path.stat().st_size  # a line break follows the first line
        if first and line != HEADER_LINE and (complete or not HEADER_LINE.startswith(line)):
            return f"log_path: {path} exists with other columns (not a season log of this version); choose another"
        return None
    ancestor = path.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"log_path: {path}: {ancestor} is not a directory"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"log_path: cannot create {path} (no write access to {ancestor})"
    return None


class SeasonLog:
    """Append-only CSV of the season log (see the module docstring)."""

    def __init__(self, path: Path):
        self.path = Path(path).expanduser()
        problem = log_path_problem(self.path)
        if problem:
            raise LogPathError(problem)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_CLOEXEC, 0o644)
        self._text = io.StringIO()
        self._writer = csv.writer(self._text)
        self.rows_written = 0
        try:
            self.repaired_bytes = self._remove_torn_end()
            if os.fstat(self._fd).st_size == 0:
                self._append(self._encode(LOG_COLUMNS))
        except BaseException:
            os.close(self._fd)
            raise

    def _remove_torn_end(self) -> int:
        """Cut the file back to just after its last line break; returns the bytes removed."""
        size = os.fstat(self._fd).st_size
        keep = size
        with open(self.path, "rb") as existing:
            while keep > 0:
                start = max(0, keep - _TAIL_READ_BYTES)
                existing.seek(start)
                chunk = existing.read(keep - start)
                if keep == size and chunk.endswith(b"\n"):
                    return 0
                newline = chunk.rfind(b"\n")
                if newline >= 0:
                    keep = start + newline + 1
                    break
                keep = start
        os.ftruncate(self._fd, keep)
        return size - keep

    def _encode(self, cells) -> bytes:
        self._text.seek(0)
        self._text.truncate()
        self._writer.writerow(cells)
        return self._text.getvalue().encode("utf-8")

    def _append(self, line: bytes) -> None:
        end = os.fstat(self._fd).st_size  # O_APPEND: the line goes here
        rest = memoryview(line)
        try:
            while rest:
                rest = rest[os.write(self._fd, rest):]
        except OSError:
            os.ftruncate(self._fd, end)  # no torn row: the file ends with its last whole row again
            raise

    def write(self, row: dict) -> None:
        """Append one day's row (missing columns empty). OSError if it could not be written: the file is then
        as it was before the call."""
        self._append(self._encode([_cell(row[column]) if column in row else "" for column in LOG_COLUMNS]))
        self.rows_written += 1

    @property
    def closed(self) -> bool:
        return self._fd < 0

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def _cell(value) -> str:
    kind = type(value)
    if kind is float:
        return repr(value)
    if kind is bool or kind is np.bool_:
        return "1" if value else "0"
    if isinstance(value, np.floating):
        return repr(float(value))
    return str(value)
