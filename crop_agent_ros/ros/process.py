"""Start and stop ROS node processes (the farm's nodes, benchmark peers) from Python, without rclpy.

Used by :mod:`.farm` (one command that grows a season over ROS), :mod:`.bench` and the ROS tests.

- ``isolated_ros_env()``: an environment for child processes that keeps discovery on this machine
  (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) on a chosen ``ROS_DOMAIN_ID``. The wheels'
  bootstrapper variables (``LD_LIBRARY_PATH``, ``_ROS_WHEELS_BOOTSTRAP_COMPLETE``) are inherited
  untouched.
- ``NodeProcess``: a child ``python -m <module> --ros-args ...``; ``stop()`` sends SIGINT (the nodes shut
  down cleanly on it), then SIGKILL after a grace period; ``kill()`` sends SIGKILL at once.
  After a SIGKILL, Fast DDS leaves its shared-memory files in /dev/shm: ``NodeProcess`` notes the files
  its own process owns (the segments whose lock files it holds) before killing it and removes, once it is
  dead, only those that no other live process also owns (a shared port). ``wait(timeout)`` on a process that
  is still running when it expires has it print where it is (Python's fault handler, on SIGABRT) before it
  raises :class:`StillRunning` with that output: a hang names its own frame.
  A node dies with the process that started it: on Linux the child asks the kernel for SIGTERM when its parent
  dies (``prctl(PR_SET_PDEATHSIG)``, kept across the bootstrapper's exec), so a SIGKILL of ``crop-sim farm``
  leaves no node running (each node has its own session, so nothing else would reach it). The signal comes when
  the *thread* that started the child ends: start nodes from a thread that outlives them (the main thread).
"""

from __future__ import annotations

import atexit
import ctypes
import ctypes.util
import os
import signal
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]  # the folder holding crop_sim_ros/ and crop_agent_ros/
SHM = Path("/dev/shm")


def pick_domain_id(salt: int = 0) -> int:
    """A ROS_DOMAIN_ID in 1..100 derived from this process id (Fast DDS on Linux allows 0..101)."""
    return 1 + (os.getpid() + salt) % 100


def isolated_ros_env(domain_id: int | None = None, base: dict | None = None) -> dict:
    """A copy of ``base`` (default os.environ) for a child ROS process: localhost discovery, the given
    domain (default: this process's ROS_DOMAIN_ID or one derived from the pid), the repository on
    PYTHONPATH (so ``python -m crop_sim_ros.sim_node`` works from a source tree)."""
    env = dict(os.environ if base is None else base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy, and it conflicts with the range above
    if domain_id is None:
        domain_id = int(env.get("ROS_DOMAIN_ID") or pick_domain_id())
    env["ROS_DOMAIN_ID"] = str(domain_id)
    path = env.get("PYTHONPATH", "")
    if str(REPO_ROOT) not in path.split(os.pathsep):
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO_ROOT), path) if p)
    env.setdefault("PYTHONUNBUFFERED", "1")
    env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
    env.setdefault("PYTHONFAULTHANDLER", "1")  # SIGABRT prints every thread's stack: NodeProcess.wait uses it
    return env


def _open_lock_files(pid: int) -> set[str]:
    """The Fast DDS lock files ('/dev/shm/fastrtps_*_el') a live process holds open: one per shared-memory
    segment it owns (its own data segment and the ports it listens on)."""
    files: set[str] = set()
    try:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if target.startswith("/dev/shm/fastrtps_") and target.endswith("_el"):
                files.add(target)
    except OSError:
        pass
    return files


def _shm_files_of(pid: int) -> set[str]:
    """The Fast DDS shared-memory files a live process owns: each segment whose lock file it holds, the lock
    file itself, and for a port segment its named semaphore. (Segments of peers that it only maps to read
    from are not its own.)"""
    files: set[str] = set()
    for lock in _open_lock_files(pid):
        segment = lock.removesuffix("_el")
        files |= {lock, segment}
        name = Path(segment).name
        if name.startswith("fastrtps_port"):
            files.add(str(SHM / f"sem.{name}_mutex"))
    return files


def _mapped_ports_of(pid: int) -> set[str]:
    """The Fast DDS port segments a live process maps (its own and those of the peers it sends to)."""
    ports: set[str] = set()
    try:
        with open(f"/proc/{pid}/maps") as maps:
            for line in maps:
                path = line.rstrip("\n").split(maxsplit=5)[-1].removesuffix(" (deleted)")
                if path.startswith("/dev/shm/fastrtps_port") and not path.endswith("_el"):
                    ports.add(path)
    except OSError:
        pass
    return ports


def _held_by_others(paths: set[str], exclude: set[int]) -> set[str]:
    """Those of ``paths`` that belong to a segment whose lock file another live process holds (a port that
    other participants also listen on)."""
    locks = {p for p in paths if p.endswith("_el")}
    held_locks: set[str] = set()
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) in exclude:
            continue
        held_locks |= _open_lock_files(int(entry)) & locks
        if held_locks == locks:
            break
    held: set[str] = set()
    for lock in held_locks:
        segment = lock.removesuffix("_el")
        held |= {lock, segment, str(SHM / f"sem.{Path(segment).name}_mutex")}
    return held & paths


def clean_shm_files(paths: set[str], dead_pids: set[int]) -> list[str]:
    """Remove those of ``paths`` (files owned by processes now dead) that no live process still owns.
    Peers that still map a removed segment keep their mapping (unlinking only removes the name)."""
    removed = []
    for path in sorted(paths - _held_by_others(paths, dead_pids)):
        try:
            os.unlink(path)
            removed.append(path)
        except OSError:
            pass
    return removed


# Port segments a killed process had open. A process that sends to a port counts itself among the port's
# users; killed, it never signs off, so when the port's owner (a peer: another node, this test process) later
# exits cleanly it leaves its port segment behind. clean_dead_ports() removes those once nobody listens on them
# (no live lock file) and no other live process maps them; it runs again when this process exits.
_DEAD_PORTS: set[str] = set()


def _mapped_by_others(paths: set[str]) -> set[str]:
    """Those of ``paths`` that another live process maps. (This process keeps Fast DDS's cache of the ports
    it once sent to until it exits; it no longer uses the port of a dead peer.)"""
    mapped: set[str] = set()
    own = str(os.getpid())
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or entry == own:
            continue
        try:
            with open(f"/proc/{entry}/maps") as maps:
                for line in maps:
                    path = line.rstrip("\n").split(maxsplit=5)[-1].removesuffix(" (deleted)")
                    if path in paths:
                        mapped.add(path)
        except OSError:
            continue
    return mapped


def clean_dead_ports() -> list[str]:
    """Remove the port segments of processes this process killed, where nobody listens on them again (no
    live lock file) and no other live process maps them. Returns what was removed."""
    removed = []
    if not _DEAD_PORTS:
        return removed
    listening = set()
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            listening |= _open_lock_files(int(entry))
    candidates = {p for p in _DEAD_PORTS if os.path.exists(p) and p + "_el" not in listening}
    busy = _mapped_by_others(candidates)
    for port in candidates - busy:
        for path in (port, port + "_el", str(SHM / f"sem.{Path(port).name}_mutex")):
            try:
                os.unlink(path)
                removed.append(path)
            except OSError:
                pass
    return removed  # the ports stay listed: a peer may re-create one later; at exit this runs again


atexit.register(clean_dead_ports)


PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _load_prctl():
    """libc's ``prctl``, looked up once here (not in the forked child, where loading a library could deadlock);
    None where there is none (not Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    prctl.argtypes = [ctypes.c_int, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong, ctypes.c_ulong]
    prctl.restype = ctypes.c_int
    return prctl


_PRCTL = _load_prctl()


def die_with_parent(parent_pid: int, signum: int = signal.SIGTERM):
    """A ``preexec_fn`` that has the child receive ``signum`` when its parent dies (None where the platform
    cannot). It runs in the child between fork and exec: if the parent died before the request was made (the
    child was already handed to another process, so ``getppid()`` differs), the child exits at once."""
    if _PRCTL is None:
        return None
    prctl = _PRCTL

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, int(signum), 0, 0, 0)
        if os.getppid() != parent_pid:
            os._exit(128 + int(signum))

    return preexec


class StillRunning(subprocess.TimeoutExpired):
    """A child process outlived a wait; ``output`` holds what it printed, its stacks at the end."""

    def __str__(self) -> str:
        return f"{super().__str__()}; what it printed, ending with its stacks:\n{self.output}"


class NodeProcess:
    """A ROS node (or any Python module) in a child process."""

    def __init__(self, module: str, ros_args: list[str] | None = None, args: list[str] | None = None,
                 env: dict | None = None, name: str | None = None, log_path: str | Path | None = None,
                 python: str | None = None):
        self.module = module
        self.name = name or module
        command = [python or sys.executable, "-m", module, *(args or [])]
        if ros_args:
            command += ["--ros-args", *ros_args]
        self.command = command
        self.log_path = Path(log_path) if log_path else None
        self._log = open(self.log_path, "ab") if self.log_path else None
        self.process = subprocess.Popen(command, env=env if env is not None else isolated_ros_env(),
                                        cwd=str(REPO_ROOT),
                                        stdout=self._log if self._log else subprocess.PIPE,
                                        stderr=subprocess.STDOUT, start_new_session=True,
                                        preexec_fn=die_with_parent(os.getpid()))
        self.pid = self.process.pid
        self._shm: set[str] = set()
        self._ports: set[str] = set()
        self._killed = False

    def poll(self) -> int | None:
        return self.process.poll()

    def output(self) -> str:
        """What the process printed (its log file, or its pipe once it has ended)."""
        if self.log_path:
            if self._log:
                self._log.flush()
            return self.log_path.read_text(errors="replace")
        if self.process.poll() is not None and self.process.stdout:
            return self.process.stdout.read().decode(errors="replace")
        return ""

    def wait(self, timeout: float | None = None) -> int:
        """The exit status. A process still running after ``timeout`` seconds is asked for its stacks (SIGABRT:
        the fault handler prints them, then the process dies) and :class:`StillRunning` is raised."""
        try:
            return self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self._end(signal.SIGABRT, grace=10.0)
            self._killed = True  # an aborted process leaves its shared-memory files as a killed one does
            self._cleanup()
            raise StillRunning(self.command, timeout, output=self.output()) from None

    def _remember_shm(self) -> None:
        # the bootstrapper exec()s in place, so the pid stays the node's pid
        self._shm |= _shm_files_of(self.pid)
        self._ports |= _mapped_ports_of(self.pid)

    def kill(self) -> None:
        """SIGKILL now (a crash), then remove the shared-memory files only this process held."""
        if self.process.poll() is None:
            self._remember_shm()
            self.process.kill()
            self.process.wait()
            self._killed = True
        self._cleanup()

    def stop(self, grace: float = 5.0) -> int:
        """SIGINT (clean shutdown), SIGKILL after ``grace`` seconds. Returns the exit code."""
        if self.process.poll() is None:
            self._end(signal.SIGINT, grace)
        self._cleanup()
        return self.process.returncode

    def _end(self, signum: int, grace: float) -> None:
        """Send ``signum``; SIGKILL if the process still runs ``grace`` seconds later."""
        self._remember_shm()
        try:
            self.process.send_signal(signum)
            self.process.wait(grace)
        except subprocess.TimeoutExpired:
            self._remember_shm()
            self.process.kill()
            self.process.wait()
            self._killed = True

    def _cleanup(self) -> None:
        if self._killed:
            clean_shm_files(self._shm, {self.pid})
            _DEAD_PORTS.update(self._ports)
            clean_dead_ports()
        self._shm, self._ports = set(), set()
        if self._log:
            self._log.close()
            self._log = None

    def __enter__(self) -> "NodeProcess":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

