"""Issue 65's yardstick: the extended feature ladder, difficulties up to 1.5, and the
generated set of 60 seeded courses with a summary line per difficulty
(``stratawalk bench physics --courses generated-set``)."""

import hashlib
import json

import numpy as np
import pytest

from planner.bench.physics import (
    expand_physics_courses,
    family_summary,
    job_id,
    physics_jobs,
    physics_rows,
    render_markdown,
    summarize,
)
from planner.cli.main import main
from planner.core.errors import InputError
from planner.world.course_gen import (
    EXTRA_KINDS,
    FEATURE_KINDS,
    LADDER,
    MAX_LEVEL_M,
    MAX_STEP_M,
    _level_change,
    course_spec,
    generate_course,
    generated_set_family,
    generated_set_names,
    ladder_course_names,
)
from planner.world.terrain import Terrain, load_terrain

ALL_KINDS = FEATURE_KINDS + EXTRA_KINDS
DX_M = 0.001

# sha256 (16 hex digits) of json.dumps(spec, sort_keys=True), computed with the generator
# before difficulties above 1 were allowed (3f609d2): the physics benchmarks' courses
OLD_SPECS = {
    "gen:0": "bccee0c257238ec5",
    "gen:1": "c4e0a7240493fbb0",
    "gen:5": "330f0c478252d607",
    "gen:19": "32afdea971b77f41",
    "gen:7:0.6": "ef21cec10a25ee01",
    "gen:8822:0.6": "2a27fa8c3197f67c",
    "gen:3:0.3:2": "9f4e3b91e1a357c8",
    "gen:11:1:3:rough+step+gap+stairs+stepping_stones+incline+barrier": "caf9abc2f8784d6e",
    "gen:2:0.6:3:step+incline": "8fd7064684e75c6a",
}


def _digest(spec: dict) -> str:
    return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:16]


def test_the_old_names_give_the_same_courses():
    for name, digest in OLD_SPECS.items():
        assert _digest(course_spec(name)) == digest, name
    gen0 = course_spec("gen:0")  # a few exact fields, readable when a digest changes
    assert gen0["name"] == "gen:0" and gen0["length"] == 3.9
    assert len(course_spec("gen:7:0.6")["segments"]) >= 3


def test_the_set_is_60_courses_that_build():
    names = generated_set_names()
    assert len(names) == 60 and len(set(names)) == 60
    tail = ":3:" + "+".join(ALL_KINDS)
    for d in ("0.6", "1", "1.3"):
        mine = [n for n in names if n.startswith("gen:") and n.split(":")[2] == d]
        assert mine == [f"gen:{seed}:{d}{tail}" for seed in range(20)]
        assert {generated_set_family(n) for n in mine} == {f"generated d={d}"}
    for name in names:
        terrain = load_terrain(name)
        assert terrain.name == name
        features = [s["kind"] for s in terrain.spec["segments"][1:-1]]
        assert features and "flat" not in features, name
        x = np.arange(0.6, 3.0, 0.005)
        relief = np.ptp(terrain.height_sharp(x, np.zeros_like(x)))
        # stones may lie off y = 0 and a relief be low there: the others show along it
        assert relief > 0.005 or {"stepping_stones", "rough"} & set(features), name
    # all seven kinds appear in the set (as the spec's kinds: an incline is a slope)
    seen = {s["kind"] for n in names for s in course_spec(n)["segments"]}
    assert seen >= {"rough", "step", "gap", "stairs", "stepping_stones", "slope", "barrier"}
    small = generated_set_names(2, (0.5,), ("step",), 2.0)
    assert small == ["gen:0:0.5:2:step", "gen:1:0.5:2:step"]
    with pytest.raises(InputError, match="--difficulty"):
        generated_set_names(difficulties=(1.6,))


def test_difficulty_above_one_goes_past_the_maxima():
    steps = [
        abs(s["height"])
        for seed in range(200)
        for s in generate_course(seed, 3.0, 1.3, ("step",))["segments"]
        if s["kind"] == "step"
    ]
    assert MAX_STEP_M < max(steps) <= 0.02 + 1.3 * 0.06 + 1e-9 < 0.11
    one = [
        abs(s["height"])
        for seed in range(50)
        for s in generate_course(seed, 3.0, 1.0, ("step",))["segments"]
        if s["kind"] == "step"
    ]
    assert max(one) <= MAX_STEP_M
    # at 1.5 every size stays physically valid and the level within MAX_LEVEL_M
    for seed in range(150):
        spec = generate_course(seed, 3.0, 1.5, ALL_KINDS)
        level = 0.0
        for seg in spec["segments"][1:-1]:
            level += _level_change(seg)
            assert abs(level) <= MAX_LEVEL_M + 1e-9, (seed, level)
            if seg["kind"] == "stairs":
                assert seg["run"] >= 0.15 - 1e-9 and 0 < abs(seg["rise"]) <= 0.08 + 1e-9
            if seg["kind"] == "stepping_stones":
                assert seg["size"] >= 0.065 - 1e-9 and seg["gap"] <= 0.065 + 1e-9
                assert seg["depth"] > 0.04
            if seg["kind"] == "gap":
                assert seg["depth"] > 0 and seg["width"] <= 0.11 + 1e-9
            if seg["kind"] == "barrier":
                assert seg["height"] <= 0.125 + 1e-9
            if seg["kind"] == "slope":
                assert abs(seg["angle_deg"]) <= 25.0 + 1e-6
        if seed < 10:
            Terrain.from_spec(spec)
    assert load_terrain("gen:4:1.5").name == "gen:4:1.5"


def test_difficulty_above_one_and_a_half_is_refused(tmp_path, capsys):
    with pytest.raises(InputError, match=r"^--difficulty: must be in \[0, 1.5\], got 1.51$"):
        generate_course(1, difficulty=1.51)
    with pytest.raises(InputError, match="course 'gen:1:1.6': difficulty"):
        load_terrain("gen:1:1.6")
    out = tmp_path / "c.yaml"
    assert main(["generate-course", "--seed", "1", "--difficulty", "1.3", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["generate-course", "--seed", "1", "--difficulty", "1.6", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--difficulty" in err and "1.5" in err
    bench = ["bench", "physics", "--courses", "flat", "--difficulty", "1.6", "--out"]
    assert main([*bench, str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--difficulty: must be in [0, 1.5]" in err


def test_the_ladder_holds_issue_65s_sizes():
    want = {
        "step": (0.06, 0.08, 0.1, 0.11, 0.12, -0.06, -0.08, -0.1, -0.12),
        "gap": (0.04, 0.08, 0.12),
        "incline": (6.0, 12.0, 18.0, 24.0),
        "barrier": (0.03, 0.06, 0.09, 0.1),
        "stairs": (0.04, 0.06, 0.08, -0.04, -0.06, -0.08),
        "stones": (0.03, 0.05, 0.07),
    }
    names = ladder_course_names()
    for kind, sizes in want.items():
        assert set(sizes) <= set(LADDER[kind]), kind
        for size in sizes:
            assert f"feat:{kind}:{size:g}" in names
    # the sizes of the earlier results tables are still there
    assert {0.12} <= set(LADDER["barrier"]) and {0.16} <= set(LADDER["gap"])
    x = np.arange(-0.5, 1.5, DX_M)
    for name, top in (("feat:step:0.11", 0.11), ("feat:barrier:0.1", 0.1)):
        terrain = load_terrain(name)
        z = terrain.height_sharp(x, np.zeros_like(x))
        assert z.max() == pytest.approx(top), name
    assert load_terrain("feat:stairs:-0.08").spec["segments"][1]["rise"] == -0.08
    assert load_terrain("feat:incline:24").name == "feat:incline:24"


def test_bench_physics_expands_the_set_into_families(tmp_path):
    courses, families = expand_physics_courses(["flat", "generated-set", "ladder"])
    assert courses[0] == "flat" and courses[1:61] == tuple(generated_set_names())
    assert courses[61:] == tuple(ladder_course_names())
    assert set(families) == set(generated_set_names())
    assert families[courses[1]] == "generated d=0.6" and families[courses[60]] == "generated d=1.3"
    some = list(courses[:2]) + [courses[25], courses[45]]
    jobs = physics_jobs(some, generated=1, out_dir=tmp_path, families=families)
    assert [j["group"] for j in jobs] == ["named", *["generated-set"] * 3, "generated"]
    assert [j.get("family") for j in jobs] == [
        None, "generated d=0.6", "generated d=1", "generated d=1.3", None,
    ]  # fmt: skip
    assert load_terrain(jobs[3]["terrain"]).name == courses[45]
    # the family does not change a job's id (--resume keeps a job run without one)
    plain = physics_jobs(some, generated=1, out_dir=tmp_path)
    assert [job_id(j) for j in plain] == [job_id(j) for j in jobs]


# ------------------------------------------------------------------------------ the summary
def _job(course, family):
    return {
        "robot": "littledog",
        "course": course,
        "group": "generated-set",
        "family": family,
        "terrain": course,
        "planner": "soft",
        "start": [0.2, 0.0],
        "goal": [3.0, 0.0],
        "modes": ["open", "feedback"],
        "time_budget_s": 120.0,
        "time_scale": 1.0,
        "plans_dir": None,
        "planned_only": True,
    }


def _sim(reached, fell=False, final_error_cm=2.0):
    return {
        "status": "ok",
        "reached": reached,
        "fell": fell,
        "final_error_cm": final_error_cm,
        "com_to_goal_cm": 3.0 if reached else 40.0,
        "message": "executed as planned" if reached else "fell",
        "wall_time_s": 10.0,
    }


def _record(job, planned, open_row, feedback_row):
    skipped = {"status": "skipped", "message": "not simulated: the plan did not reach"}
    rows = [
        {"course": job["course"], "group": job["group"], "family": job["family"], "mode": m}
        | (r if planned else skipped)
        for m, r in (("open", open_row), ("feedback", feedback_row))
    ]
    planning = {"planned": planned, "plan_reached": planned, "check_ok": True, "steps": 50}
    planning |= {"planning_time_s": 60.0, "walk_time_s": 150.0}
    return {"id": job_id(job), "job": job, "status": "ok", "planning": planning, "rows": rows}


def test_a_summary_line_per_family():
    easy, hard = "generated d=0.6", "generated d=1.3"
    jobs = [
        _job("gen:0:0.6:3:step", easy),
        _job("gen:1:0.6:3:step", easy),
        _job("gen:2:0.6:3:step", easy),
        _job("gen:0:1.3:3:step", hard),
        _job("gen:1:1.3:3:step", hard),
    ]
    recs = [
        _record(jobs[0], True, _sim(True), _sim(True)),
        _record(jobs[1], True, _sim(False, final_error_cm=7.5), _sim(False, fell=True)),
        _record(jobs[2], False, _sim(True), _sim(True)),  # not planned: skipped
        _record(jobs[3], True, _sim(False, fell=True, final_error_cm=30.0), _sim(True)),
        _record(jobs[4], False, _sim(True), _sim(True)),
    ]
    rows = physics_rows(jobs, {r["id"]: r for r in recs})
    assert {r["family"] for r in rows} == {easy, hard}
    fams = family_summary(rows)
    assert list(fams) == [easy, hard]
    assert fams[easy] == {
        "courses": 3,
        "planned": 2,
        "errors": 0,
        "modes": {
            "open": {"runs": 2, "reached": 1, "fell": 0, "within_5cm": 1},
            "feedback": {"runs": 2, "reached": 1, "fell": 1},
        },
    }
    assert fams[hard]["modes"]["open"] == {"runs": 1, "reached": 0, "fell": 1, "within_5cm": 0}
    assert fams[hard]["modes"]["feedback"] == {"runs": 1, "reached": 1, "fell": 0}
    s = summarize(rows)
    assert s["families"] == fams
    assert s["generated"]["courses"] == 0 and s["named"] == {} and s["ladder"] == {}
    result = {
        "config": {"start": [0.2, 0.0], "goal_named": [2.2, 0.0], "difficulty": 1.0,
                   "time_budget_s": 120.0, "time_scale": 1.0, "modes": ["open", "feedback"],
                   "workers": 2},
        "machine": {}, "total_time_s": 1.0, "summary": s, "rows": rows,
    }  # fmt: skip
    md = render_markdown(result)
    line = (
        "- generated d=0.6: 3 courses, 2 planned within the budget; open loop 1 reached, 0 fell, "
        "1 within 5 cm (of 2 runs); feedback (8.3) 1 reached, 1 fell (of 2 runs)"
    )
    assert line in md
    assert "- generated d=1.3: 2 courses, 1 planned within the budget; open loop 0 reached" in md
    assert md.index("## Generated set: generated d=0.6") < md.index("| gen:2:0.6:3:step |")
    assert md.index("| gen:2:0.6:3:step |") < md.index("## Generated set: generated d=1.3")
    assert md.index("## Generated set: generated d=1.3") < md.index("## Summary")
    assert "the generated set: generated d=0.6, generated d=1.3" in md
