"""Mistakes in what a user gives a command (a value, a file, a name): one line on stderr, exit status 2.

A command raises :class:`UsageError` for such a mistake; ``crop-sim`` prints ``crop-sim <command>: <message>``
and exits with EXIT_USAGE, without a traceback. Tracebacks are kept for our own bugs, so only the code that
reads the user's input converts its errors, with :func:`user_input`:

    with user_input("--task"):
        scenario = load_scenario(path)     # ValueError, KeyError (an unknown name), OSError -> UsageError
"""

from __future__ import annotations

from contextlib import contextmanager

EXIT_USAGE = 2  # as argparse and ``crop-sim validate``


class UsageError(ValueError):
    """A mistake in a command's input; the message names the argument or file and what is wrong with it."""


def one_line(error: BaseException) -> str:
    """The message of ``error`` on one line (a YAML error spans several: its lines joined with '; ')."""
    return "; ".join(line.strip() for line in str(error).splitlines() if line.strip()) or type(error).__name__


def check_range(option: str, value: int | float, low: int | float, high: int | float) -> None:
    """UsageError ``OPTION: VALUE is not in LOW..HIGH`` unless low <= value <= high (a count or a size is checked
    before anything is allocated for it; NaN is refused too)."""
    if not low <= value <= high:
        raise UsageError(f"{option}: {shown(value)} is not in {low}..{high}")


def shown(value, limit: int = 40) -> str:
    """``repr(value)`` for a message, at most ``limit`` characters and ``...`` (reprlib: a long string or a big,
    deep container is never expanded whole, so a refusal never formats an unbounded value)."""
    import reprlib
    short = reprlib.Repr()
    short.maxstring = short.maxother = limit + 2
    short.maxlevel, short.maxlist, short.maxtuple, short.maxdict, short.maxset = 2, 6, 6, 4, 6
    try:
        text = short.repr(value)
    except ValueError:  # an integer of more than 4,300 digits
        text = f"<{type(value).__name__} too long to show>"
    return text if len(text) <= limit else text[:limit] + "..."


@contextmanager
def user_input(what: str | None, errors: tuple[type[BaseException], ...] = (ValueError, KeyError, OSError)):
    """Turn ``errors`` raised while reading the user's ``what`` into a UsageError naming it (None: the
    error's message names it already)."""
    try:
        yield
    except UsageError:
        raise
    except errors as error:
        raise UsageError(one_line(error) if what is None else f"{what}: {one_line(error)}") from None


def node_arguments(program: str, argv: list[str], usage) -> int | None:
    """A ROS node's own arguments (those before ``--ros-args``): ``--help`` prints ``usage()`` (exit 0), any
    other is one line on stderr (exit 2); None when there are none and the node should run."""
    import sys
    ours = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    if any(a in ("-h", "--help") for a in ours):
        print(usage())
        return 0
    if ours:
        print(f"{program}: unknown argument {ours[0]!r}; parameters go after --ros-args (see {program} --help)",
              file=sys.stderr)
        return EXIT_USAGE
    return None


def exit_within(seconds: float, status: int = 0) -> None:
    """End the process with ``status`` after ``seconds`` unless it has exited by then (a daemon timer): a node
    stopping on a signal is gone in bounded time even if rclpy's teardown hangs (once more than 20 s here, with
    the machine loaded). Arm it only once nothing is left that must finish (the season log is closed)."""
    import os
    import threading

    watchdog = threading.Timer(seconds, os._exit, args=(status,))
    watchdog.daemon = True
    watchdog.start()
