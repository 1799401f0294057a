"""Generate a page per ``stratawalk`` command from its ``--help``, with a hand-written example.

Run by mkdocs-gen-files at build time: ``commands/<name>.md`` for each command of
``planner.cli.main.build_parser()`` (a command's sub-commands, such as ``bench theta``, are
sections of its page) and ``commands/SUMMARY.md`` for the navigation. The build fails when a
command has no example below, or an example names a command the parser no longer has.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import docinfo  # noqa: E402

# One short example per command (shell lines; `#` comments say what each does).
EXAMPLES = {
    "robot": """
stratawalk robot littledog        # legs, joints, limits, masses, reach, standing pose
stratawalk robot --list           # every robot: mass, reach, foot, servo stiffness, URDF
stratawalk robot path/to/my.urdf  # your own 4-leg, 3-joints-per-leg quadruped
""",
    "terrain": """
stratawalk terrain                                   # the named courses (terrains/*.yaml)
stratawalk terrain rough2cm --png top.png            # a course, top view in height colours
stratawalk terrain maze_two_walls --png map.png --guide 2.6,0   # cost map and guide path
""",
    "plan": """
stratawalk plan --terrain rough2cm --goal 2.2,0 --out plan.json      # soft persuasion (8.2)
stratawalk plan --terrain step10cm --goal 2.2,0 --planner recursive  # backtracking (8.5)
stratawalk plan --global --terrain barrier15cm_opening --goal 2.2,0 --time-budget 60
stratawalk plan --terrain flat --goal 2.2,0 --preset fast --out fast.json
stratawalk plan --terrain flat --config settings.yaml --print-config # the settings in force
""",
    "check": """
stratawalk check plan.json        # exit 0: every check passes; exit 1: a violation
stratawalk check plan.json --all  # print every violation, not only the first 50
""",
    "demo": """
stratawalk demo                   # LittleDog 2 m over rough2cm: out/demo/plan.json,
                                  # replay.html and figures/ (make demo runs this)
stratawalk demo --terrain stairs --out out/stairs
""",
    "bench": """
stratawalk bench theta --jit                        # Theta1-4: IPOPT vs SLSQP
stratawalk bench courses --courses named --planners soft,recursive
stratawalk bench physics --courses hard --generated 0 --modes open,feedback
stratawalk bench speed --presets default,fast
stratawalk bench robots
""",
    "replay": """
stratawalk replay plan.json                     # meshcat, http://127.0.0.1:7000/static/
stratawalk replay plan.json --html replay.html  # one self-contained file, no server
stratawalk replay plan.json --compare sim.json  # the MuJoCo execution beside the plan
""",
    "plot": """
stratawalk plot plan.json --out figures/   # top_view, stability, joints, gait (PNG)
""",
    "simulate": """
stratawalk simulate plan.json --out sim.json     # open loop at the plan's own timing
stratawalk simulate plan.json --feedback         # re-plan each step from the measured state (8.3)
stratawalk simulate plan.json --correct --noise-mm 1 --latency 0.02   # correct each step (8.4)
stratawalk simulate plan.json --trajectory plan.csv   # execute an export
""",
    "batch": """
stratawalk batch examples/scenarios.yaml --out out/batch            # local process pool
stratawalk batch examples/scenarios.yaml --out out/batch --scheduler tcp://HOST:8786  # Dask
""",
    "generate-course": """
stratawalk generate-course --seed 7 --out course.yaml --png course.png   # a random 3 m course
stratawalk generate-course --feature step:0.08 --out step8cm.yaml       # one feature
stratawalk plan --terrain gen:7:0.6          # the same course by name, to its end
""",
    "export": """
stratawalk export plan.json --rate 500 --out plan.csv   # or plan.npz
stratawalk simulate plan.json --trajectory plan.csv    # execute the export in MuJoCo
""",
}


def page(name: str, parser, summary: str, subs: list) -> str:
    """The markdown page of command ``name``."""
    lines = [f"# stratawalk {name}", "", summary[:1].upper() + summary[1:] + ".", ""]
    lines += ["## Example", "", "```bash", EXAMPLES[name].strip("\n"), "```", ""]
    lines += [
        "## Usage",
        "",
        "Every option with its unit and default: "
        f"[settings reference](../settings.md#stratawalk-{name.replace(' ', '-')}).",
        "",
        "```text",
        docinfo.help_text(parser).rstrip(),
        "```",
        "",
    ]
    for path, sp, help_ in subs:
        sub = " ".join(path)
        lines += [f"## stratawalk {sub}", "", help_ + ".", "", "```text"]
        lines += [docinfo.help_text(sp).rstrip(), "```", ""]
    return "\n".join(lines)


def main() -> None:
    """Write the command pages, their index and their navigation."""
    import mkdocs_gen_files

    parser = docinfo.build_parser()
    docinfo.check_missing_help(parser)
    cmds = docinfo.commands(parser)
    top = [c for c in cmds if len(c[0]) == 1]
    names = [path[0] for path, _, _ in top]
    missing = [n for n in names if n not in EXAMPLES]
    extra = [n for n in EXAMPLES if n not in names]
    if missing or extra:
        raise RuntimeError(
            f"docs/_gen/cli_pages.py: EXAMPLES lacks {missing} / names unknown commands {extra}"
        )
    nav = ["* [Overview](index.md)"]
    for (name,), parser_, summary in top:
        subs = [c for c in cmds if len(c[0]) > 1 and c[0][0] == name]
        with mkdocs_gen_files.open(f"commands/{name}.md", "w") as fh:
            fh.write(page(name, parser_, summary, subs))
        nav.append(f"* [{name}]({name}.md)")
    with mkdocs_gen_files.open("commands/index.md", "w") as fh:
        fh.write("# Commands\n\n`stratawalk COMMAND --help` prints the same as these pages.\n\n")
        fh.write("| command | what it does |\n|---|---|\n")
        for (name,), _, summary in top:
            fh.write(f"| [`{name}`]({name}.md) | {docinfo.md_escape(summary)} |\n")
        fh.write("\n```text\n" + docinfo.help_text(parser).rstrip() + "\n```\n")
    with mkdocs_gen_files.open("commands/SUMMARY.md", "w") as fh:
        fh.write("\n".join(nav) + "\n")


if __name__ == "<run_path>":  # mkdocs-gen-files runs this file with runpy.run_path
    main()
