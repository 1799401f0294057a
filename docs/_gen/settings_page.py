"""Generate the settings reference (``settings.md``) from the code at build time.

Every command-line option (``planner.cli.main.build_parser()``), the planner settings of
``stratawalk plan`` and its ``--config`` YAML (``planner.planning.settings.SETTINGS``, with
LittleDog's values from ``stratawalk plan --print-config``), the settings dataclasses, the
terrain files' fields (read from the terrain kinds' code), the batch scenario fields and the
environment variables: with unit, default and effect, so the page cannot drift from the code.
"""

from __future__ import annotations

import inspect
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import docinfo  # noqa: E402
from docinfo import md_escape as esc  # noqa: E402

# The settings dataclasses a user passes from Python, with their API page.
DATACLASSES = (
    "planner.problems.options.LocalSettings",
    "planner.problems.options.ThetaOptions",
    "planner.planning.recursive.RecursiveSettings",
    "planner.planning.global_plan.GlobalSettings",
    "planner.planning.global_plan.CostWeights",
    "planner.sim.model.SimSettings",
)


def _obj(path: str):
    module, name = path.rsplit(".", 1)
    return getattr(__import__(module, fromlist=[name]), name)


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(esc(c) if c != "" else "" for c in row) + " |" for row in rows]
    return out + [""]


def cli_section() -> list[str]:
    """The options of every command, a table each."""
    lines = [
        "## Command-line options",
        "",
        "Each command's options as its parser defines them (`stratawalk COMMAND --help`). "
        "The unit comes from the option's help (`[m]`) or its name; an empty default is "
        "*not given* (the option's effect says what then). The planner settings of "
        "`plan` (`--mu` to `--time-budget`) have no default of their own on the command "
        "line: see [Planner settings](#planner-settings) for the values in force.",
        "",
    ]
    for path, parser, summary in docinfo.commands():
        if docinfo._subparsers(parser) is not None:
            lines += [f"### stratawalk {' '.join(path)}", "", esc(summary) + ".", ""]
            lines += ["Sub-commands: " + ", ".join(f"`{c}`" for c in parser_choices(parser))]
            lines += [""]
            continue
        rows = [
            [f"`{o['name']}`", f"`{o['value']}`" if o["value"] else "", o["default"], o["unit"],
             o["effect"]]
            for o in docinfo.options(path, parser)
        ]  # fmt: skip
        lines += [f"### stratawalk {' '.join(path)}", "", esc(summary) + ".", ""]
        lines += _table(["option", "value", "default", "unit", "effect"], rows)
    return lines


def parser_choices(parser) -> list[str]:
    """The sub-commands of a command's parser."""
    return list(docinfo._subparsers(parser).choices)


def planner_section() -> list[str]:
    """The planner settings (``SETTINGS``) with the values in force, and the presets."""
    from planner.planning import settings as st
    from planner.problems.options import LocalSettings, ThetaOptions

    printed = docinfo.run_cli(["plan", "--terrain", "flat", "--print-config"])
    values = dict(line.split(": ", 1) for line in printed.splitlines() if ": " in line)
    local_docs = docinfo.field_docs(LocalSettings)
    theta_docs = docinfo.field_docs(ThetaOptions)
    rows = []
    for s in st.SETTINGS:
        if s.kind in ("float", "int"):
            lo = (">" if s.lo_open else ">=") + f" {s.lo:g}"
            if s.hi == float("inf"):
                rng = lo
            else:  # a whole bound in full (the seed's 2^31 - 1)
                rng = lo + ", <= " + (f"{s.hi:.0f}" if s.hi > 1e5 else f"{s.hi:g}")
            rng += ", whole" if s.kind == "int" else ""
        elif s.kind == "choice":
            rng = " \\| ".join(s.choices)
        else:
            rng = "the four legs, each once"
        owner = "thetaoptions" if s.name.startswith("theta.") else "localsettings"
        field = s.name.split(".", 1)[-1]
        documented = field in (theta_docs if owner == "thetaoptions" else local_docs)
        effect = s.help + (f" ([more](#{owner}))" if documented else "")
        rows.append(
            [f"`{s.name}`", f"`{s.option}`", docinfo.unit_of(s.name, s.help), rng,
             values.get(s.name, ""), effect]
        )  # fmt: skip
    doc = inspect.getdoc(st) or ""
    example = doc.split("::", 1)[1].split("\n\n")[1] if "::" in doc else ""
    lines = [
        "## Planner settings",
        "",
        "What `stratawalk plan` takes as options and a `--config` YAML file takes by name "
        "([`planner.planning.settings`][planner.planning.settings]): the options override the "
        "file, which overrides `--preset`, which overrides the defaults. *In force* is "
        "LittleDog's value on flat ground, as `stratawalk plan --terrain flat --print-config` "
        "prints it now (lengths and times scale with the robot's legs); the plan records "
        "the values in force under `stats.settings`.",
        "",
    ]
    lines += _table(["YAML name", "option", "unit", "range", "in force", "effect"], rows)
    lines += ["A settings file:", "", "```yaml", inspect.cleandoc(example), "```", ""]
    lines += [
        "### Presets",
        "",
        "`stratawalk plan --preset NAME` ([`PRESETS`][planner.planning.settings.PRESETS]), "
        "under `--config` and the options; lengths (names ending in `_m`) scale with the "
        "robot's legs.",
        "",
    ]
    for name, values_ in st.PRESETS.items():
        lines += [f"`{name}`:", ""]
        lines += _table(["setting", "value"], [[f"`{k}`", repr(v)] for k, v in values_.items()])
    return lines


def dataclass_section() -> list[str]:
    """A table per settings dataclass."""
    lines = [
        "## Settings in Python",
        "",
        "The dataclasses behind the settings, for use from Python (e.g. "
        "`plan_walk(..., settings=LocalSettings(step_m=0.05))`); every field with its "
        "default and its description from the class docstring or the field's comment.",
        "",
    ]
    for path in DATACLASSES:
        cls = _obj(path)
        rows = [
            [f"`{r['name']}`", f"`{r['type']}`", f"`{r['default']}`", r["unit"], r["effect"]]
            for r in docinfo.dataclass_rows(cls)
        ]
        summary = (inspect.getdoc(cls) or "").split("\n\n")[0]
        lines += [f"### {cls.__name__}", "", f"[`{path}`][{path}]: {esc(summary)}", ""]
        lines += _table(["field", "type", "default", "unit", "effect"], rows)
    return lines


def _terrain_unit(row: dict) -> str:
    name = row["name"]
    if row["method"] in ("integer", "string") or name in ("stones", "heights", "segments"):
        return ""
    if name == "friction":
        return ""
    if name.endswith("_deg"):
        return "deg"
    if name == "metres_per_unit":
        return "m per unit"
    return "m"


def _field_rows(rows: list[dict]) -> list[list[str]]:
    return [[f"`{r['name']}`", r["default"], r["range"], _terrain_unit(r), r["hint"]] for r in rows]


def terrain_section() -> list[str]:
    """The terrain files' fields: top level, course segments, each kind."""
    from planner.world import terrain

    doc = inspect.getdoc(terrain) or ""
    spec = doc.split("Spec (YAML)\n", 1)[1].split("\n\n")[0] if "Spec (YAML)" in doc else ""
    top, seg = docinfo.terrain_top_fields()
    descriptions = docinfo.kind_descriptions()
    lines = [
        "## Terrain files",
        "",
        "A terrain is a YAML file (`terrains/NAME.yaml`, or any path given to `--terrain`), "
        "read by [`Terrain`][planner.world.terrain.Terrain]. The fields below are those the "
        "code reads, with their defaults and ranges as it checks them; an unknown field is "
        "an error. Lengths are metres in the world frame.",
        "",
        inspect.cleandoc(spec),
        "",
        "### Top level",
        "",
    ]
    lines += _table(["field", "default", "range", "unit", "note"], _field_rows(top))
    lines += [
        "`x_min` defaults to -0.5 (a height field: its grid's extent); `length` is required "
        "but for a course (the sum of its segments) or a height field (its grid's).",
        "",
        "### Course segments",
        "",
        esc(descriptions.get("course", "")),
        "",
    ]
    lines += _table(["field", "default", "range", "unit", "note"], _field_rows(seg))
    lines += ["Each segment also takes its kind's fields, with x relative to its start.", ""]
    for kind, rows in docinfo.terrain_kind_fields().items():
        lines += [f"### kind: {kind}", "", esc(descriptions.get(kind, "")), ""]
        if rows:
            lines += _table(["field", "default", "range", "unit", "note"], _field_rows(rows))
        else:
            lines += ["No fields of its own.", ""]
    return lines


def batch_section() -> list[str]:
    """The batch scenario file's job fields."""
    from planner.bench import batch

    doc = inspect.getdoc(batch) or ""
    example = doc.split("Scenarios file (YAML)::", 1)[1].split("\n\n")[1]
    rows = [
        [f"`{f}`", repr(batch.DEFAULTS[f]) if f in batch.DEFAULTS else "required",
         docinfo.unit_of(f)]
        for f in batch.JOB_FIELDS
    ]  # fmt: skip
    lines = [
        "## Batch scenarios",
        "",
        "`stratawalk batch FILE.yaml` ([`planner.bench.batch`][planner.bench.batch]): each "
        "job has these fields (planners: " + ", ".join(batch.PLANNER_NAMES) + "); "
        "`defaults` fills the missing ones, `jobs` lists jobs, `matrix` makes every "
        "combination.",
        "",
    ]
    lines += _table(["field", "default", "unit"], rows)
    lines += ["```yaml", inspect.cleandoc(example), "```", ""]
    return lines


def robots_section() -> list[str]:
    """The robots by name."""
    from planner.body.robot import robot_names

    return [
        "## Robots",
        "",
        "A robot is a URDF file, not a YAML file: `--robot` takes one of these names "
        "(LittleDog from `models/`, the others from example-robot-data) or a URDF path "
        "([`load_robot`][planner.body.robot.load_robot]); `stratawalk robot NAME` shows what "
        "the planner reads from it.",
        "",
        ", ".join(f"`{n}`" for n in robot_names()),
        "",
    ]


def env_section() -> list[str]:
    """The ``STRATAWALK_*`` environment variables and the modules that read them."""
    seen: dict[str, list[str]] = {}
    for path in sorted((docinfo.ROOT / "planner").rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        module = ".".join(path.relative_to(docinfo.ROOT).with_suffix("").parts)
        module = module.removesuffix(".__init__")
        for name in sorted(set(re.findall(r"STRATAWALK_[A-Z_]+", text))):
            seen.setdefault(name.rstrip("_"), []).append(module)
    rows = [
        [f"`{name}`", ", ".join(f"[`{m}`][{m}]" for m in modules)]
        for name, modules in sorted(seen.items())
    ]
    lines = [
        "## Environment variables",
        "",
        "Read by these modules (their pages say what each does).",
        "",
        "| variable | read in |",
        "|---|---|",
    ]
    lines += [f"| {a} | {b} |" for a, b in rows]
    return lines + [""]


def main() -> None:
    """Write ``settings.md``."""
    import mkdocs_gen_files

    lines = [
        "# Settings reference",
        "",
        "Generated from the code at every docs build: the command-line parser, the settings "
        "table of the planner, the settings dataclasses and their docstrings, and the "
        "fields the terrain kinds read.",
        "",
    ]
    lines += cli_section() + planner_section() + dataclass_section()
    lines += terrain_section() + batch_section() + robots_section() + env_section()
    with mkdocs_gen_files.open("settings.md", "w") as fh:
        fh.write("\n".join(lines))


if __name__ == "<run_path>":  # mkdocs-gen-files runs this file with runpy.run_path
    main()
