"""Ray in tests: every Ray process runs inside a network namespace that has only loopback.

Ray picks its node address by probing an outside address and then binds to the machine's external
interface; inside a namespace with only ``lo`` up it can only use 127.0.0.1. :class:`LoopbackNamespace`
holds one namespace for a test (a holder process made by ``unshare -n``; commands enter it with
``nsenter``), so a head node, a second raylet and the driver share it. Every process started through it
is stopped by its own process id (SIGTERM, then SIGKILL), never by ``ray stop`` (which would stop other
tests' Ray processes too). Each namespace gets its own short ``RAY_TMPDIR`` (Ray's socket paths must stay
under the 107-character limit of Unix sockets) and its own token (``RAY_AUTH_MODE=token``: Ray 2.60 asks for
a token on a cluster started by ``ray start``, and every process of the cluster must share it).
"""

from __future__ import annotations

import os
import secrets
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


class LoopbackNamespace:
    """A loopback-only network namespace for one test; use as a context manager."""

    def __init__(self):
        self.holder: subprocess.Popen | None = None
        self.processes: list[subprocess.Popen] = []
        self.tmpdir = tempfile.mkdtemp(prefix="ray", dir="/tmp")
        self.token_file = Path(self.tmpdir) / "auth_token"
        self.token_file.write_text(secrets.token_hex(32))

    def __enter__(self) -> "LoopbackNamespace":
        for unshare in (["unshare", "-n"], ["unshare", "-rn"]):
            holder = subprocess.Popen([*unshare, "sh", "-c", "ip link set lo up && echo up && exec sleep 86400"],
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            if holder.stdout.readline().strip() == "up":
                self.holder = holder
                break
            holder.kill()
            holder.wait()
        if self.holder is None:
            raise RuntimeError("cannot make a loopback-only network namespace (`unshare -n` / `unshare -rn` and "
                               "`ip link set lo up` failed): Ray tests must not bind an outside interface")
        return self

    def __exit__(self, *exc) -> None:
        for process in reversed(self.processes):
            stop(process)
        if self.holder is not None:
            self._stop_the_rest()
            self.holder.kill()
            self.holder.wait()
        shutil.rmtree(self.tmpdir, ignore_errors=True)

    def members(self) -> list[int]:
        """Process ids in this namespace other than its holder (Ray workers a raylet left behind, ...)."""
        namespace = os.readlink(f"/proc/{self.holder.pid}/ns/net")
        found = []
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and int(entry.name) != self.holder.pid:
                try:
                    if os.readlink(entry / "ns" / "net") == namespace:
                        found.append(int(entry.name))
                except OSError:
                    continue
        return found

    def _stop_the_rest(self, timeout: float = 10.0) -> None:
        for sig in (signal.SIGTERM, signal.SIGKILL):
            for pid in self.members():
                try:
                    os.kill(pid, sig)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + timeout
            while self.members() and time.monotonic() < deadline:
                time.sleep(0.2)

    @property
    def env(self) -> dict:
        return {**os.environ, "RAY_TMPDIR": self.tmpdir, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
                "RAY_GRACEFUL_SHUTDOWN_DRAIN_TIMEOUT_S": "0",  # a test's node has nothing to drain
                "RAY_AUTH_TOKEN_PATH": str(self.token_file),
                "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}

    def command(self, argv: list[str]) -> list[str]:
        return ["nsenter", "-t", str(self.holder.pid), "-n", *(["-U", "--preserve-credentials"]
                                                               if self._user_namespace() else []), "--", *argv]

    def _user_namespace(self) -> bool:
        return os.readlink(f"/proc/{self.holder.pid}/ns/user") != os.readlink("/proc/self/ns/user")

    def popen(self, argv: list[str], **kwargs) -> subprocess.Popen:
        """Start ``argv`` in the namespace (its own process group); stopped when the namespace closes."""
        kwargs.setdefault("env", self.env)
        process = subprocess.Popen(self.command(argv), start_new_session=True, **kwargs)
        self.processes.append(process)
        return process

    def run(self, argv: list[str], timeout: float, **kwargs) -> subprocess.CompletedProcess:
        kwargs.setdefault("env", self.env)
        kwargs.setdefault("capture_output", True)
        kwargs.setdefault("text", True)
        return subprocess.run(self.command(argv), timeout=timeout, **kwargs)

    def start_ray_node(self, cpus: int, port: int | None = None, head_address: str | None = None,
                       timeout: float = 90.0) -> subprocess.Popen:
        """``ray start --block`` as a head (on ``port``) or as a node joining ``head_address``, in the
        background; returns once the cluster lists it."""
        argv = [str(BIN / "ray"), "start", "--block", "--num-cpus", str(cpus), "--node-ip-address", "127.0.0.1",
                "--disable-usage-stats"]
        if head_address is None:
            argv += ["--head", "--port", str(port), "--include-dashboard", "false"]
            address = f"127.0.0.1:{port}"
        else:
            argv += ["--address", head_address]
            address = head_address
        log = open(Path(self.tmpdir) / f"node-{len(self.processes)}.log", "w")
        process = self.popen(argv, stdout=log, stderr=subprocess.STDOUT)
        expected = 1 + sum(1 for p in self.processes[:-1] if "ray" in " ".join(map(str, p.args)))
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if process.poll() is not None:
                raise RuntimeError(f"ray start exited {process.returncode}: "
                                   + (Path(self.tmpdir) / log.name).read_text()[-2000:])
            probe = self.run([sys.executable, "-c", _COUNT_NODES, address], timeout=60)
            if probe.returncode == 0 and int(probe.stdout.strip() or 0) >= expected:
                return process
            time.sleep(1.0)
        raise TimeoutError(f"the Ray node ({' '.join(argv)}) did not join within {timeout:.0f} s")


_COUNT_NODES = """
import sys, logging, ray
ray.init(address=sys.argv[1], logging_level=logging.ERROR, log_to_driver=False)
print(sum(1 for n in ray.nodes() if n.get("Alive")))
"""


def stop(process: subprocess.Popen, timeout: float = 30.0) -> None:
    """SIGTERM to the process (its group: ``ray start --block`` stops what it started), then SIGKILL."""
    if process.poll() is not None:
        return
    try:
        os.killpg(process.pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    try:
        process.wait(timeout)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
