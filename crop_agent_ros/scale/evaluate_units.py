"""``crop-sim evaluate --task T --address ...``: the evaluation's units as Ray tasks.

Each unit (:class:`crop_agent_ros.learning.evaluation_units.Unit`: a policy on a set with one noise seed, or the
oracle on a chunk of a set's seasons) is one Ray task of one CPU, spread over the nodes, computed by the same
:func:`~crop_agent_ros.learning.evaluation_units.run_unit` as a run without ``--address``. Everything a worker
needs goes to it as data (put once in the object store): the set (its scenario dataclass), the set's terms,
the tuned rule (the object) and each agent as the bytes of its ``.zip`` and ``.json``
(:class:`~crop_agent_ros.learning.evaluation_units.AgentFile`). Workers read the weather from
``CROP_SIM_DATA_DIR`` (:func:`crop_agent_ros.scale.cluster.connect`) and need this package installed.
"""

from __future__ import annotations

from dataclasses import replace

from ..learning.evaluation_units import ORACLE, AgentFile, run_unit
from .cluster import this_node

LOCAL_RAY = "local"  # --address local: a private Ray instance on this machine

# a worker's agents, loaded once per content: a worker process runs many units of one evaluation
_WORKER_AGENTS: dict = {}


def unit_task(unit, evaluation_set, terms: dict, source):
    """One unit on a Ray worker: ``source`` is the rule, an AgentFile, or None for the oracle."""
    policy = source.policy(_WORKER_AGENTS) if isinstance(source, AgentFile) else source
    return replace(run_unit(unit, evaluation_set, terms, policy), node=this_node())


def run_on_ray(units: list, sets: list, terms: list[dict], sources: dict, address: str, cpus: int | None, log):
    """Every unit's result, in the order of ``units``, and the cluster they ran on. ``address``: ``local`` (a
    private instance with ``cpus`` CPUs), ``auto`` or HOST:PORT (UsageError if no cluster answers)."""
    import ray

    from . import cluster as ray_cluster
    connected = ray_cluster.connect(None if address == LOCAL_RAY else address, cpus)
    try:
        log(f"{connected.describe()}; {len(units)} units as Ray tasks (1 CPU each)")
        task = ray.remote(num_cpus=1)(unit_task).options(scheduling_strategy="SPREAD")
        set_refs = [ray.put(s) for s in sets]
        terms_refs = [ray.put(t) for t in terms]
        source_refs = {key: ray.put(source) for key, source in sources.items()}
        # the oracle's units first: they are the longest, and a long unit started last would end the run alone
        first = sorted(range(len(units)), key=lambda i: units[i].policy != ORACLE)
        submitted = {i: task.remote(units[i], set_refs[units[i].set_index], terms_refs[units[i].set_index],
                                    source_refs.get(units[i].policy)) for i in first}
        refs = [submitted[i] for i in range(len(units))]
        pending, reported = list(refs), 0
        while pending:
            _, pending = ray.wait(pending, num_returns=1)
            tenth = 10 * (len(refs) - len(pending)) // len(refs)
            if tenth > reported:
                reported = tenth
                log(f"units done: {len(refs) - len(pending)}/{len(refs)}")
        return ray.get(refs), connected
    finally:
        ray_cluster.disconnect()
