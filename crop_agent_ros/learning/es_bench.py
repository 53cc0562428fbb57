"""``crop-sim es-bench [--task T] [--repeats 3]``: field-days per second of one evolution
strategies generation, the numpy learner (:func:`.evolution.generation`, the published agents') beside the JAX
learner (:mod:`.jax_evolution`, one jitted call), interleaved. ``--whole-recipe``: whole training runs instead
(``crop-sim train --algorithm es``, seed 0, each learner in turn, ``--repeats`` rounds; start-up, compilation and
validation checkpoints included), their wall and CPU seconds.

Both run the task's ES recipe (``hyperparams/es.yml``: ``pairs`` x 2 candidates on ``seasons`` seasons, the
64 x 64 network) on the same seasons with the same terms (the first generation of seed 0), from the same
initial network, each the best of ``repeats`` runs taken in turn
(:func:`~crop_sim_ros.throughput.interleaved_best_rates`: both see the same moments' load); the JAX compilation
is timed apart and excluded. A generation's field-days are every candidate's days of every season (what the
recipe's ``timesteps`` counts). The CPU model and the load are printed with every figure: on a shared machine
compare the ratio, not the figures of another run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

EXAMPLE_TASK = "benton-quota"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--task", default=EXAMPLE_TASK, help=f"a family task (default {EXAMPLE_TASK})")
    parser.add_argument("--repeats", type=int, default=3, help="best of this many generations each (default 3)")
    parser.add_argument("--pairs", type=int, default=None, help="candidate pairs (default: the task's recipe)")
    parser.add_argument("--seasons", type=int, default=None, help="seasons a generation (default: the recipe's)")
    parser.add_argument("--whole-recipe", action="store_true",
                        help="time whole `crop-sim train` runs of the recipe (seed 0), each learner in turn, "
                             "--repeats rounds, instead of one generation")
    parser.add_argument("--timesteps", type=int, default=None,
                        help="field-days of a whole run (with --whole-recipe; default: the recipe's)")


def _learners(task: str, overrides: dict):
    """(settings, scenario, actor, interface) of ``task``'s ES recipe with ``overrides``, a fresh network."""
    from crop_sim_ros.task import get_scenario
    from ..policies.learned import AgentInterface
    from . import hyperparameters as hp
    from .evolution import ActorVector
    from .train_task import ES_CONTAINER_LOG_STD, actor_container, fit_scaler

    settings = hp.resolve(task, "es", True, overrides)
    scenario = get_scenario(task)
    interface = AgentInterface(fit_scaler(scenario, 0))
    model = actor_container(interface.input_size,
                            {"net_arch": list(settings.net_arch), "log_std_init": ES_CONTAINER_LOG_STD}, seed=0)
    return settings, scenario, ActorVector(model.policy), interface


def _numpy_generation(settings, scenario, actor, interface):
    """(run_once, field-days) of the numpy learner's first generation of seed 0 (the same one every run)."""
    from .evolution import GENERATIONS_STREAM, Adam, generation

    theta = actor.get()

    def run_once() -> int:
        rng = np.random.default_rng([0, GENERATIONS_STREAM])
        return generation(actor, theta, Adam(actor.size), rng, interface, scenario, settings, 0)[1]

    return run_once, run_once()


def _jax_generation(settings, scenario, actor, interface, echo):
    """(run_once, field-days) of the JAX learner's first generation of seed 0, compiled first (timed apart)."""
    import jax
    from .evolution import GENERATIONS_STREAM, generation_seasons
    from .jax_evolution import JaxEvolution, generation_key

    start = time.perf_counter()
    learner = JaxEvolution(scenario, interface, actor, settings)
    state = learner.start(actor.get(), jax.random.key(0))
    seasons, terms = generation_seasons(np.random.default_rng([0, GENERATIONS_STREAM]), scenario, settings.seasons)

    def run_once() -> int:
        new_state, _, days = learner.generation(state, generation_key(0, 0), seasons, terms, settings.learning_rate)
        jax.block_until_ready(new_state)
        return days

    days = run_once()
    echo(f"  (JAX: built, compiled and run once in {time.perf_counter() - start:.1f} s; "
         f"{jax.devices()[0].platform}, candidates split over {learner.parts} devices, float64 environment, "
         f"float32 network)")
    return run_once, days


def bench_es(task: str = EXAMPLE_TASK, repeats: int = 3, overrides: dict | None = None, echo=print) -> dict:
    """Measure and print the figures (see the module docstring); returns the rates by name and their ratio."""
    import jax
    from crop_sim_ros.throughput import MachineLoad, figure_line, interleaved_best_rates

    settings, scenario, actor, interface = _learners(task, overrides or {})
    echo(f"ES generation of {task}: {2 * settings.pairs} candidates x {settings.seasons} seasons, network "
         f"{list(settings.net_arch)}, best of {repeats} (numpy and JAX in turn)")
    with jax.enable_x64(True):
        runs = {"numpy": _numpy_generation(settings, scenario, actor, interface),
                "jax": _jax_generation(settings, scenario, actor, interface, echo)}
        load = MachineLoad()
        rates = interleaved_best_rates(runs, repeats)
    echo(figure_line("ES generation, numpy learner (evolution.py)", rates["numpy"], "field-days", load))
    echo(figure_line("ES generation, JAX learner (evosax, one jit call)", rates["jax"], "field-days", load))
    ratio = rates["jax"].per_s / rates["numpy"].per_s
    echo(f"  JAX / numpy: {ratio:.2f}x (wall), {rates['jax'].per_cpu_s / rates['numpy'].per_cpu_s:.2f}x (CPU time)")
    return {**rates, "ratio": ratio}


def bench_whole_recipe(task: str = EXAMPLE_TASK, rounds: int = 1, overrides: dict | None = None,
                       echo=print) -> dict:
    """Whole ``crop-sim train --algorithm es`` runs of ``task`` (seed 0, the recipe with ``overrides``), the numpy
    learner then the JAX learner, ``rounds`` times: each run's wall time, the CPU time of its process (all
    threads) and what other processes used meanwhile. Returns the best wall and CPU seconds per learner."""
    import resource
    import subprocess
    import sys
    import tempfile
    from crop_sim_ros.throughput import MachineLoad

    extra = [arg for key, value in (overrides or {}).items() for arg in ("--hyperparams", f"{key}={value}")]
    seconds = {"numpy": [], "jax": []}
    echo(f"whole ES recipe of {task}, seed 0, {rounds} round(s), numpy and JAX learner in turn")
    with tempfile.TemporaryDirectory(prefix="es-bench-") as folder:
        for round_index in range(rounds):
            for backend, runs in seconds.items():
                command = [sys.executable, "-m", "crop_agent_ros.cli", "train", "--task", task, "--algorithm", "es",
                           "--seed", "0", "--no-progress", "--hyperparams", f"backend={backend}", *extra,
                           "--out", f"{folder}/{backend}-{round_index}"]
                before, load, start = resource.getrusage(resource.RUSAGE_CHILDREN), MachineLoad(), time.perf_counter()
                done = subprocess.run(command, capture_output=True, text=True)
                wall = time.perf_counter() - start
                after, figures = resource.getrusage(resource.RUSAGE_CHILDREN), load.figures()
                if done.returncode != 0:
                    last = (done.stderr.strip().splitlines() or ["no message"])[-1]
                    raise RuntimeError(f"crop-sim train --hyperparams backend={backend} failed: {last}")
                cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
                runs.append((wall, cpu))
                others = max(sum(figures["cpu_busy"]) - (cpu + figures["this_process_cpus"] * wall) / wall, 0.0)
                echo(f"  round {round_index + 1}, {backend} learner: {wall:.1f} s wall, {cpu:.1f} s CPU "
                     f"(CPUs busy {', '.join(f'{b:.0%}' for b in figures['cpu_busy'])}; other processes "
                     f"{others:.2f} CPUs)")
    best = {backend: (min(w for w, _ in runs), min(c for _, c in runs)) for backend, runs in seconds.items()}
    (numpy_wall, numpy_cpu), (jax_wall, jax_cpu) = best["numpy"], best["jax"]
    echo(f"  numpy / JAX time: {numpy_wall / jax_wall:.2f}x (wall), {numpy_cpu / jax_cpu:.2f}x (CPU time); "
         f"best of each: numpy {numpy_wall:.1f} s wall, {numpy_cpu:.1f} s CPU; JAX {jax_wall:.1f} s, {jax_cpu:.1f} s")
    return best


def run(args: argparse.Namespace) -> int:
    import os
    from crop_sim_ros.throughput import machine_summary
    from crop_sim_ros.usage import check_range
    from crop_sim_ros.task import get_scenario, scenario_names
    from crop_sim_ros.usage import UsageError, shown
    check_range("--repeats", args.repeats, 1, 100)
    if args.task not in scenario_names() or not get_scenario(args.task).is_family_task:
        raise UsageError(f"--task {shown(args.task)}: not a family task (e.g. {EXAMPLE_TASK})")
    if args.timesteps is not None and not args.whole_recipe:
        raise UsageError("--timesteps: only with --whole-recipe (a generation's field-days are the recipe's)")
    overrides = {key: value for key, value in (("pairs", args.pairs), ("seasons", args.seasons),
                                               ("timesteps", args.timesteps)) if value is not None}
    print(f"machine: {machine_summary()}")
    if args.whole_recipe:
        from . import hyperparameters as hp
        hp.resolve(args.task, "es", True, overrides)  # bad values refused here, in one line, before any run
        bench_whole_recipe(args.task, args.repeats, overrides)
    else:
        bench_es(args.task, args.repeats, overrides)
    print(f"machine after the run: load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0

