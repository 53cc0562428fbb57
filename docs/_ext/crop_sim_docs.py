"""Sphinx directives that write the reference tables of the manual from the code, at build time.

The tables (task ids, observation layouts, terms, model parameters, ROS names, parameters and QoS) live in
the package, in module docstrings and data; copying them into pages would let the two drift. Each
directive renders Markdown and hands it to MyST, so the pages stay MyST and the tables look like the
hand-written ones.

- ``task-group NAME``: every registered Gymnasium task of one group (``paper``, ``farm-terms``, ``sensing``,
  ``climates``; see :func:`task_group`), with its id, observation table, action, reward, constraints and
  episode end. A registered task that no page renders is a build warning (an error under ``-W``).
- ``docstring-tables MODULE``: the reST tables of a module's docstring, with the columns named in
  ``:columns:``, each under its caption (the section title or the paragraph before it).
- ``ros-topics``, ``ros-parameters NODE``, ``ros-qos``: the simulator's topics and services, a node's
  parameters, the QoS profiles with the reason each was chosen.
- ``package-layout PACKAGE``: every module of a package with the first sentence of its docstring.

:func:`cli_parser` is the ``crop-sim`` parser as sphinx-argparse renders it (``docs/cli.md``).
"""

from __future__ import annotations

import importlib
import io
import inspect
import math
import re
from pathlib import Path

import docutils.core
from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

LOGGER = logging.getLogger(__name__)

# The groups of tasks, one page each, in the order of the manual.
TASK_GROUPS = ("paper", "farm-terms", "sensing", "climates")


# --- reading the code --------------------------------------------------------------------------------------

def registered_tasks() -> list[tuple[str, str, object]]:
    """(Gymnasium id, scenario name, EnvSpec) of every task ``crop_sim_ros.task`` registers, in registry order.
    Ids come from the registry itself, so the manual follows whatever naming rule the package applies."""
    import gymnasium

    import crop_sim_ros.task  # noqa: F401  (registers the ids)

    tasks = []
    for env_id, spec in gymnasium.registry.items():
        if str(spec.entry_point).startswith("crop_sim_ros.") and "scenario" in (spec.kwargs or {}):
            tasks.append((env_id, spec.kwargs["scenario"], spec))
    return tasks


def built_in_scenario(name: str):
    """A built-in scenario read from its YAML without checking that its weather files exist: the manual
    describes the task, it never runs it, so it builds without the reference data."""
    from crop_sim_ros.task.scenario import SCENARIO_DIR, load_scenario

    return load_scenario(SCENARIO_DIR / f"{name}.yaml")


def task_group(scenario) -> str:
    """The manual's group of a task: the paper's task (any weather), or a family task by what it changes from
    the family's base (``benton-money``): imperfect or no soil-water sensing; other weather (sites, sowing
    dates, delta-changed climates, mixtures of them); otherwise money, quota and pump capacity."""
    if not scenario.is_family_task:
        return "paper"
    base = built_in_scenario("benton-money")
    if (scenario.limits.paw_dropout_probability > 0 or not scenario.limits.paw_sensor
            or scenario.noise.paw_mm != base.noise.paw_mm):
        return "sensing"
    if (scenario.weather, scenario.sowing_date) != (base.weather, base.sowing_date):
        return "climates"
    return "farm-terms"


def docstring_tables(text: str) -> list[tuple[str, list[str], list[list[str]]]]:
    """(caption, header, rows) of each table in a reST docstring; the caption is the title of the section the
    table is in, or the paragraph just before it. Roles Sphinx would resolve (``:mod:``) read as plain text."""
    # Sphinx's roles need a build environment that a standalone parse lacks: read them as literals.
    plain = re.sub(r":[\w:.-]+:`([^`]*)`", r"``\1``", inspect.cleandoc(text))
    doctree = docutils.core.publish_doctree(
        plain, settings_overrides={"report_level": 5, "halt_level": 5, "warning_stream": io.StringIO()})
    tables = []
    for table in doctree.findall(nodes.table):
        rows = [[" ".join(entry.astext().split()) for entry in row.findall(nodes.entry)]
                for row in table.findall(nodes.row)]
        caption = ""
        index = table.parent.index(table)
        previous = table.parent[index - 1] if index > 0 else None
        if isinstance(previous, nodes.paragraph):
            caption = " ".join(previous.astext().split())
        elif isinstance(table.parent, nodes.section):
            caption = table.parent[0].astext()
        tables.append((caption, rows[0], rows[1:]))
    return tables


def loose_simple_table(text: str) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the first reST simple table in ``text``, read by gaps of two or more spaces instead of
    the rule's column edges, so a cell wider than its column (which docutils refuses) still reads. A line
    whose first column is blank continues the last cell of the row above."""
    lines = inspect.cleandoc(text).splitlines()
    rules = [i for i, line in enumerate(lines) if re.fullmatch(r"=+( +=+)+", line.strip())]
    if len(rules) < 3:
        raise ValueError("no reST simple table with a header")
    header = re.split(r"\s{2,}", lines[rules[0] + 1].strip())
    rows: list[list[str]] = []
    for line in lines[rules[1] + 1:rules[2]]:
        if not line.strip():
            continue
        if line.startswith(" "):
            rows[-1][-1] += " " + line.strip()
        else:
            cells = re.split(r"\s{2,}", line.strip(), maxsplit=len(header) - 1)
            rows.append(cells + [""] * (len(header) - len(cells)))
    return header, rows


def markdown_sections(docstring: str) -> dict[str, str]:
    """The ``## Title`` sections of a Markdown docstring (Gymnasium's style), title -> body."""
    sections, title = {}, None
    for line in inspect.cleandoc(docstring).splitlines():
        heading = re.match(r"^## (.+)$", line)
        if heading:
            title = heading.group(1).strip()
            sections[title] = []
        elif title is not None:
            sections[title].append(line)
    return {name: "\n".join(body).strip() for name, body in sections.items()}


def markdown_table_rows(text: str) -> list[list[str]]:
    """The body rows of the first pipe table in ``text`` (header and rule dropped)."""
    rows = [[cell.strip() for cell in line.strip().strip("|").split("|")]
            for line in text.splitlines() if line.strip().startswith("|")]
    return rows[2:]


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown pipe table."""
    def cell(value: str) -> str:
        return str(value).replace("|", "\\|").replace("\n", " ")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return lines + [""]


def number(value: float) -> str:
    if math.isinf(value):
        return "-inf" if value < 0 else "inf"
    return f"{value:g}"


def value_range(value) -> str:
    """A terms range (``Range``) as ``low-high`` or one number."""
    return number(value.low) if value.fixed else f"{number(value.low)}-{number(value.high)}"


# --- the task pages ----------------------------------------------------------------------------------------

def observation_descriptions() -> dict[int, str]:
    """Column -> description: the paper's 20 from the environment's docstring table, the family's 9 from the
    layout module's."""
    from crop_sim_ros.task import env, layout

    observation = markdown_sections(env.IrrigationEnv.__doc__)["Observation Space"]
    described = {int(row[0]): row[1] for row in markdown_table_rows(observation)}
    (_, header, rows), = docstring_tables(layout.__doc__)
    for row in rows:
        if row[0].isdigit():
            described.setdefault(int(row[0]), row[header.index("value")])
    return described


def noise_std(scenario, column: str) -> str:
    """The observation noise standard deviation of a column in this scenario ('-' for exact values)."""
    noise = scenario.noise
    name = column.removeprefix("forecast_") if column.startswith("forecast_") else column
    if column.startswith("forecast_") or column in ("biomass_t_ha", "paw_mm"):
        value = getattr(noise, name, None)
        if value is not None:
            return number(value)
    return "-"


def observation_table(scenarios: list) -> list[str]:
    """The observation table of a group: its layout's columns with units and lower bounds, the noise of each
    task (one column per distinct noise setting)."""
    described = observation_descriptions()
    layout = scenarios[0].layout
    noises = {}
    for scenario in scenarios:
        noises.setdefault(scenario.noise, []).append(scenario.name)
    header = ["#", "name", "unit", "low", "description"]
    if len(noises) == 1:
        header.append("noise std")
    else:
        header += [f"noise std ({', '.join(names)})" for names in noises.values()]
    rows = []
    for i, column in enumerate(layout.columns):
        by_noise = [noise_std(names_scenario, column.name) for names_scenario in
                    (next(s for s in scenarios if s.noise == noise) for noise in noises)]
        rows.append([str(i), f"`{column.name}`", column.unit, number(column.low), described.get(i, ""), *by_noise])
    return table(header, rows)


def weather_text(scenario) -> str:
    """Where a task's seasons come from, in a few words."""
    weather = scenario.weather
    sown = f", sown {scenario.sowing_date:%B} {scenario.sowing_date.day}" if scenario.sowing_date else ""
    if weather.kind == "generator":
        if weather.spread is not None:
            return f"{weather.n_seasons:,} generated `{weather.generator}` seasons{sown}, each its own climate"
        return f"{weather.n_seasons:,} generated seasons of `{weather.generated_climate}`{sown}"
    if weather.kind == "mixture":
        return "the seasons of " + ", ".join(f"`{name}`" for name in weather.mixture)
    files = ", ".join(f"`{Path(season.path).name}`" for season in weather.seasons)
    return f"{len(weather.seasons)} real season{'s' if len(weather.seasons) > 1 else ''} ({files})"


def terms_table(scenarios: list) -> list[str]:
    """What each task sets beyond the crop and the weather, one row per task: the water cost (paper's task),
    or money, quota, pump capacity and the soil-water sensor (family tasks)."""
    if not scenarios[0].is_family_task:
        return table(["task", "irrigation cost C_I, t/ha per mm", "action bound, mm/d"],
                     [[f"`{s.name}`", number(s.irrigation_cost_per_mm), number(s.max_irrigation_mm)]
                      for s in scenarios])
    rows = []
    for s in scenarios:
        economics, limits = s.economics, s.limits
        rows.append([f"`{s.name}`", value_range(economics.tuber_price_usd_per_t),
                     f"{value_range(economics.water_price_usd_per_mm)} + "
                     f"{value_range(economics.pumping_energy_usd_per_mm)}",
                     number(economics.event_cost_usd),
                     "none" if limits.quota_mm is None else value_range(limits.quota_mm),
                     "none" if limits.capacity_mm_per_day is None else number(limits.capacity_mm_per_day),
                     "none" if not limits.paw_sensor else
                     f"noise {number(s.noise.paw_mm)} mm, {limits.paw_dropout_probability:.0%} missing",
                     str(limits.nominal_season_days)])
    return table(["task", "tuber price, USD/t", "water + pumping, USD/mm", "event cost, USD", "quota, mm",
                  "capacity, mm/d", "PAW sensor", "nominal season, d"], rows)


def task_markdown(group: str, tasks: list) -> list[str]:
    """The body of one group's page: its tasks, then what they share (observation, action, reward,
    constraints, episode end), the shared parts read from the environment's docstring."""
    from crop_sim_ros.task import core, env

    sections = markdown_sections(env.IrrigationEnv.__doc__)
    scenarios = [scenario for _, scenario, _ in tasks]
    lines = ["## Tasks", ""]
    rows = []
    for env_id, scenario, spec in tasks:
        steps = spec.max_episode_steps
        rows.append([f"`{env_id}`", f"`{scenario.name}`", scenario.description or "",
                     weather_text(scenario), f"{steps} days" if steps else "-"])
    lines += table(["Gymnasium id", "scenario (CLI, ROS `scenario:=`)", "what it is", "weather",
                    "max_episode_steps"], rows)
    lines += ["Every task grows " + ", ".join(sorted({f"{s.cultivar} {s.crop}" for s in scenarios}))
              + " on the " + ", ".join(sorted({f"{s.soil}" for s in scenarios})) + " soil at "
              + ", ".join(sorted({number(s.co2_ppm) for s in scenarios})) + " ppm CO2. ET0: "
              + ", ".join(sorted({s.et0_method.replace('_', '-') for s in scenarios})) + ".", ""]

    lines += ["## Observation", "",
              f"`Box(low, inf, ({scenarios[0].layout.size},), float32)`. Noise is Gaussian; a noisy value "
              "below its physical bound is clipped to it. The policy reads columns by name "
              "(`crop_sim_ros.task.layout`).", ""]
    lines += observation_table(scenarios)

    lines += ["## Action", "", sections["Action Space"], ""]
    if group != "paper":
        lines += ["The irrigation applied is the action, cut to the pump capacity and to the quota left "
                  "(`info[\"irrigation_applied_mm\"]`).", ""]

    lines += ["## Reward", ""]
    if group == "paper":
        lines += [sections["Rewards"], ""]
    else:
        lines += [inspect.cleandoc(core.reward.__doc__).replace("\n", " ") + " In USD/ha: the dry yield is "
                  "valued at the fresh tuber price over the dry-matter fraction; water costs the water price "
                  "plus the pumping energy per mm.", ""]
        lines += ["Money terms (`crop_sim_ros.task.terms.Economics`) and their defaults:", ""]
        lines += terms_docstring_table(0)

    lines += ["## Constraints and terms", "",
              "A range is drawn uniformly per field at each reset and observed; one number is fixed.", ""]
    lines += terms_table(scenarios)
    if group != "paper":
        lines += ["Water rights, the irrigation system and the sensor (`crop_sim_ros.task.terms.FarmLimits`):", ""]
        lines += terms_docstring_table(1)

    lines += ["## Starting state", "", sections["Starting State"], ""]
    lines += ["## Episode end", "", sections["Episode End"], ""]
    lines += ["## Reference scores", "",
              "The oracle's return and each rule's and agent's regret on these tasks, with 95 % confidence "
              "intervals, are in the {doc}`leaderboard </leaderboard>`.", ""]
    return lines


def terms_docstring_table(index: int) -> list[str]:
    """Table ``index`` of ``crop_sim_ros.task.terms``' docstring (0: money, 1: water rights and sensing)."""
    from crop_sim_ros.task import terms

    _, header, rows = docstring_tables(terms.__doc__)[index]
    return table(["Name", "Description", "Unit", "Default"],
                 [[f"`{r[header.index('Name')]}`", r[header.index("Description")], r[header.index("Unit")],
                   r[header.index("Default")]] for r in rows])


class TaskGroupDirective(SphinxDirective):
    required_arguments = 1

    def run(self):
        group = self.arguments[0]
        if group not in TASK_GROUPS:
            raise self.error(f"task-group: unknown group {group!r}; groups: {', '.join(TASK_GROUPS)}")
        tasks = [(env_id, built_in_scenario(name), spec) for env_id, name, spec in registered_tasks()]
        mine = [task for task in tasks if task_group(task[1]) == group]
        if not mine:
            raise self.error(f"task-group {group}: no registered task is in this group")
        rendered = self.env.domaindata.setdefault("crop_sim_docs", {}).setdefault("rendered_tasks", {})
        for env_id, _, _ in mine:
            rendered[env_id] = self.env.docname
        return parse_markdown(self, task_markdown(group, mine))


def check_every_task_rendered(app, env):
    """Each registered task is on a page of the manual (else a warning, an error under -W)."""
    rendered = env.domaindata.get("crop_sim_docs", {}).get("rendered_tasks", {})
    for env_id, _, _ in registered_tasks():
        if env_id not in rendered:
            LOGGER.warning("registered task %s is on no page of the manual (no task-group directive renders it)",
                           env_id)


def purge_rendered(app, env, docname):
    rendered = env.domaindata.get("crop_sim_docs", {}).get("rendered_tasks", {})
    for env_id in [key for key, page in rendered.items() if page == docname]:
        del rendered[env_id]


def merge_rendered(app, env, docnames, other):
    env.domaindata.setdefault("crop_sim_docs", {}).setdefault("rendered_tasks", {}).update(
        other.domaindata.get("crop_sim_docs", {}).get("rendered_tasks", {}))


# --- module docstring tables -------------------------------------------------------------------------------

class DocstringTablesDirective(SphinxDirective):
    """The reST tables of a module's docstring, with the columns of ``:columns:`` (in that order)."""

    required_arguments = 1
    option_spec = {"columns": directives.unchanged_required}

    def run(self):
        module = importlib.import_module(self.arguments[0])
        columns = [c.strip() for c in self.options["columns"].split(",")]
        found = docstring_tables(module.__doc__ or "")
        if not found:
            raise self.error(f"docstring-tables: {self.arguments[0]}'s docstring has no table")
        lines = []
        for caption, header, rows in found:
            missing = [c for c in columns if c not in header]
            if missing:
                raise self.error(f"docstring-tables: a table of {self.arguments[0]} has no column "
                                 f"{', '.join(missing)} (columns: {', '.join(header)})")
            picked = [[f"`{row[header.index(c)]}`" if c == "Name" else row[header.index(c)] for c in columns]
                      for row in rows]
            lines += ([f"**{caption}**", ""] if caption else []) + table(columns, picked)
        return parse_markdown(self, lines)


# --- ROS ---------------------------------------------------------------------------------------------------

class RosTopicsDirective(SphinxDirective):
    """The simulator node's topics and services (``crop_sim_ros.ros_interface``'s table)."""

    def run(self):
        from crop_sim_ros import ros_interface as ri

        header, rows = loose_simple_table(ri.__doc__)
        return parse_markdown(self, table(header, [[cell.replace("``", "`") for cell in row] for row in rows]))


class RosParametersDirective(SphinxDirective):
    """A node's ROS parameters: ``sim`` (``crop_sim_ros.sim_node.PARAMETERS``) or ``agent``
    (``crop_agent_ros.ros.agent.PARAMETERS``)."""

    required_arguments = 1

    def run(self):
        if self.arguments[0] == "sim":
            from crop_sim_ros.sim_parameters import PARAMETERS
            rows = [[f"`{name}`", type(spec.default).__name__, f"`{spec.default!r}`",
                     f"{number(spec.low)}..{number(spec.high)}" if spec.low is not None else "",
                     spec.description + (f" ({spec.constraints})" if spec.constraints else "")]
                    for name, spec in PARAMETERS.items()]
        elif self.arguments[0] == "agent":
            from crop_agent_ros.ros.agent import PARAMETERS
            rows = []
            for name, (default, descriptor) in PARAMETERS.items():
                ranges = list(descriptor.floating_point_range) + list(descriptor.integer_range)
                bounds = f"{number(ranges[0].from_value)}..{number(ranges[0].to_value)}" if ranges else ""
                extra = f" ({descriptor.additional_constraints})" if descriptor.additional_constraints else ""
                rows.append([f"`{name}`", type(default).__name__, f"`{default!r}`", bounds,
                             descriptor.description + extra])
        else:
            raise self.error(f"ros-parameters: unknown node {self.arguments[0]!r}; nodes: sim, agent")
        return parse_markdown(self, table(["parameter", "type", "default", "range", "meaning"], rows))


def qos_reasons(source: str) -> dict[str, str]:
    """NAME -> the comment block just above ``NAME = QoSProfile(`` in a module's source."""
    reasons, comment = {}, []
    for line in source.splitlines():
        if line.startswith("#"):
            comment.append(line.lstrip("#").strip())
            continue
        assignment = re.match(r"^([A-Z_]+) = QoSProfile\(", line)
        if assignment:
            reasons[assignment.group(1)] = " ".join(comment)
        if not line.startswith(" "):
            comment = []
    return reasons


class RosQosDirective(SphinxDirective):
    """Every QoS profile of ``crop_sim_ros.ros_interface`` with its settings and the reason for it."""

    def run(self):
        from rclpy.qos import HistoryPolicy, QoSProfile

        from crop_sim_ros import ros_interface as ri

        reasons = qos_reasons(Path(ri.__file__).read_text())
        rows = []
        for name, profile in vars(ri).items():
            if not isinstance(profile, QoSProfile):
                continue
            history = ("keep all" if profile.history == HistoryPolicy.KEEP_ALL
                       else f"keep last {profile.depth}")
            rows.append([f"`{name}`", history, profile.reliability.name.lower().replace("_", " "),
                         profile.durability.name.lower().replace("_", " "), reasons.get(name, "")])
        return parse_markdown(self, table(["profile", "history", "reliability", "durability", "why"], rows))


# --- the command line -------------------------------------------------------------------------------------

def terminal_text_as_rest(text: str) -> str:
    """Help text written for a terminal (an indented block after a line ending in ':') as reST: the block
    becomes a literal block, which sphinx-argparse would otherwise parse as a mangled block quote."""
    return re.sub(r":\n(?=    )", "::\n\n", text)


def cli_parser():
    """``crop_agent_ros.cli.build_parser()`` for sphinx-argparse (``docs/cli.md``), with each command's
    description and epilog readable as reST; the options, arguments and texts are the parser's own."""
    import argparse

    from crop_agent_ros.cli import build_parser

    parser = build_parser()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for command in action.choices.values():
                for attribute in ("description", "epilog"):
                    if getattr(command, attribute):
                        setattr(command, attribute, terminal_text_as_rest(getattr(command, attribute)))
    return parser


# --- the package layout ------------------------------------------------------------------------------------

def first_sentence(path: Path) -> str:
    """The first sentence of a module's docstring, read from its source (nothing is imported)."""
    import ast

    docstring = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    paragraph = " ".join(docstring.split("\n\n")[0].split())
    match = re.match(r"(.+?[.:])(\s|$)", paragraph)
    return (match.group(1) if match else paragraph).rstrip(":.")


class PackageLayoutDirective(SphinxDirective):
    """Each package's sub-packages and modules with the first sentence of their docstrings, from the tree as
    it is: the layout cannot fall behind a move."""

    required_arguments = 1

    def run(self):
        root = Path(self.env.srcdir).parent / self.arguments[0]
        if not (root / "__init__.py").is_file():
            raise self.error(f"package-layout: {root} is not a package")
        rows = []
        for path in sorted(root.rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            relative = path.relative_to(root.parent)
            if path.name == "__init__.py":
                name = f"`{relative.parent.as_posix()}/`"
            else:
                name = f"`{relative.as_posix()}`"
            rows.append([name, first_sentence(path)])
        return parse_markdown(self, table(["module", "what it is"], rows))


# --- plumbing ----------------------------------------------------------------------------------------------

def parse_markdown(directive: SphinxDirective, lines: list[str]) -> list[nodes.Node]:
    """Parse generated Markdown (headings allowed) in the directive's place."""
    container = nodes.container()
    directive.state.nested_parse(StringList(lines, source=directive.get_source_info()[0]),
                                 directive.content_offset, container, match_titles=True)
    return container.children


def setup(app):
    app.add_directive("task-group", TaskGroupDirective)
    app.add_directive("docstring-tables", DocstringTablesDirective)
    app.add_directive("ros-topics", RosTopicsDirective)
    app.add_directive("ros-parameters", RosParametersDirective)
    app.add_directive("ros-qos", RosQosDirective)
    app.add_directive("package-layout", PackageLayoutDirective)
    app.connect("env-check-consistency", check_every_task_rendered)
    app.connect("env-purge-doc", purge_rendered)
    app.connect("env-merge-info", merge_rendered)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True, "env_version": 1}
