"""One way to reach Ray: a private local instance, or an existing cluster (``--address``).

- ``address=None``: start a private local instance with ``cpus`` CPUs (default: the CPUs this process may
  use), no dashboard, no usage statistics; it ends with the command. Ray cannot be held to loopback by a
  setting: it resolves 127.0.0.1 to the machine's outside address and its servers listen on every interface
  (checked in a namespace with a second interface: the node took 10.77.0.1, the GCS and raylet ports listened
  on ``*``). Ray 2.60 protects such a local instance with a token; to keep it off the network entirely, run the
  command in a namespace that has only loopback (``unshare -n``, ``ip link set lo up``), as the tests and
  ``crop-sim sweep-bench`` do.
- ``address="auto"`` or ``"HOST:PORT"``: join a running cluster (``ray start --head`` on one machine,
  ``ray start --address=HOST:PORT`` on the others); its CPUs are the cluster's.

Every worker of the job gets ``CROP_SIM_DATA_DIR`` (the reference data directory as the driver resolved it:
on a real cluster it must exist at that path on every node, e.g. a shared file system) and one thread per
numerical library (one CPU per trial or task).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from crop_sim_ros.usage import UsageError

ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
_ADDRESS = re.compile(r"^(auto|(\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.-]+):\d{1,5})$")


@dataclass(frozen=True)
class Cluster:
    """What the command is connected to: ``local`` (its own instance) or the address it joined, and the
    cluster's nodes (id, address, CPUs) when it connected."""

    address: str
    nodes: tuple[dict, ...]

    def describe(self) -> str:
        nodes = ", ".join(f"{node['node']} ({node['address']}, {node['cpus']:g} CPU)" for node in self.nodes)
        return f"Ray {self.address}: {len(self.nodes)} node(s): {nodes}"


def check_address(address: str | None) -> str | None:
    """``address`` if it is None, ``auto`` or HOST:PORT, else UsageError."""
    if address is None or _ADDRESS.match(address):
        return address
    raise UsageError(f"--address: {address!r} is neither 'auto' nor HOST:PORT (e.g. 127.0.0.1:6379)")


def connect(address: str | None, cpus: int | None = None) -> Cluster:
    """Connect this process to Ray (see the module docstring); UsageError if no cluster answers at
    ``address`` or ``cpus`` is not positive."""
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")   # no usage report to an outside server
    import logging

    import ray
    from crop_sim_ros.task.scenario import DATA_DIR_ENV, default_data_dir

    address = check_address(address)
    worker_env = {**ONE_THREAD, DATA_DIR_ENV: str(default_data_dir().resolve())}
    common = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING,
                  runtime_env={"env_vars": worker_env}, configure_logging=True)
    if address is None:
        if cpus is not None and cpus < 1:
            raise UsageError(f"--cpus: {cpus} is not a positive number of CPUs")
        ray.init(num_cpus=cpus or len(os.sched_getaffinity(0)), **common)
        where = "local"
    else:
        probe(address)
        try:
            ray.init(address=address, **common)
        except ConnectionError as error:
            raise _no_cluster(address, _first_line(error)) from None
        where = address
    return Cluster(where, tuple(nodes()))


def probe(address: str | None, timeout_s: float = 5.0) -> None:
    """For a HOST:PORT address: UsageError unless something accepts a TCP connection there within ``timeout_s``
    (``ray.init`` itself waits minutes on an address where nothing listens). None and ``auto``: nothing to do."""
    import socket
    if address is None or address == "auto":
        return
    host, _, port = address.rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s):
            pass
    except OSError as error:
        raise _no_cluster(address, error.strerror or str(error)) from None


def _no_cluster(address: str, why: str) -> UsageError:
    return UsageError(f"--address {address}: no Ray cluster answers there ({why}); start one with `ray start "
                      "--head` or leave --address out for a local instance")


def nodes() -> list[dict]:
    """The cluster's live nodes: short id (first 8 hex digits), address and CPUs, in a stable order."""
    import ray
    alive = [n for n in ray.nodes() if n.get("Alive")]
    return sorted(({"node": n["NodeID"][:8], "node_id": n["NodeID"], "address": n.get("NodeManagerAddress", "?"),
                    "cpus": float(n.get("Resources", {}).get("CPU", 0.0))} for n in alive),
                  key=lambda n: n["node_id"])


def this_node() -> dict:
    """Inside a Ray task or actor: the node it runs on (short id, full id, address) and its process id."""
    import ray
    context = ray.get_runtime_context()
    return {"node": context.get_node_id()[:8], "node_id": context.get_node_id(),
            "address": ray.util.get_node_ip_address(), "pid": os.getpid()}


def disconnect() -> None:
    import ray
    if ray.is_initialized():
        ray.shutdown()


def _first_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return text[0] if text else type(error).__name__
