"""Bad input to every command: one line naming the option or file, exit 2, before any work.

Each case here was a traceback, a hang or a silently wrong result once (issue 19).
"""

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from planner.cli.main import main

LITTLEDOG_URDF = Path(__file__).parents[1] / "models" / "littledog" / "littledog.urdf"


def _one_line_error(capsys, *names):
    """The captured stderr: one line that names each of ``names``."""
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err, err
    for name in names:
        assert str(name) in err, err
    return err


# ------------------------------------------------------------------------------ outputs
def test_outputs_are_checked_before_any_work(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    a_file = tmp_path / "a_file"
    a_file.write_text("keep me")
    cases = [
        (["plot", str(path), "--out", str(a_file)], "--out"),
        (["plot", str(path), "--out", str(tmp_path / "p"), "--dpi", "-5"], "--dpi"),
        (["plot", str(path), "--out", str(a_file / "sub")], "is a file"),
        (["replay", str(path), "--html", str(tmp_path)], "--html"),
        (["replay", str(path), "--html", str(tmp_path / "r.txt")], ".html"),
        (["export", str(path), "--out", str(a_file / "x.csv")], "is a file"),
        (["terrain", "flat", "--png", str(tmp_path)], "--png"),
        (["batch", str(a_file), "--out", str(a_file)], "--out"),
        (["plan", "--terrain", "flat", "--goal", "0.5,0", "--out", str(tmp_path)], "--out"),
        (["generate-course", "--seed", "1", "--out", str(a_file)], "is a file"),
        (["generate-course", "--seed", "1", "--out", str(a_file / "c.yaml")], "is a file"),
        (["bench", "physics", "--courses", "flat", "--out", str(a_file)], "is a file"),
        (["bench", "courses", "--out", str(a_file)], "is a file"),
        (["bench", "theta", "--out", str(a_file)], "is a file"),
    ]
    for args, expect in cases:
        assert main(args) == 2, args
        _one_line_error(capsys, expect)
    assert a_file.read_text() == "keep me"
    assert not (tmp_path / "p").exists()


def test_outputs_are_written_whole_with_the_usual_mode(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    out = tmp_path / "new" / "folder" / "replay.html"
    assert main(["replay", str(path), "--html", str(out), "--geometry", "collision"]) == 0
    assert out.stat().st_mode & 0o777 == 0o666 & ~_umask()
    assert [p.name for p in out.parent.iterdir()] == ["replay.html"]  # no temporary left


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


# ------------------------------------------------------------------------------ terrains
@pytest.mark.parametrize(
    "field, value", [("length", "1.0e+300"), ("x_min", "-1.0e+308"), ("y_min", "-1.0e+6")]
)
def test_terrain_of_absurd_extent_is_refused(field, value, tmp_path, capsys):
    text = (Path(__file__).parents[1] / "terrains" / "flat.yaml").read_text()
    course = tmp_path / "huge.yaml"
    course.write_text(re.sub(rf"(?m)^{field}:.*$", f"{field}: {value}", text))
    assert main(["terrain", str(course), "--png", str(tmp_path / "t.png")]) == 2
    _one_line_error(capsys, "huge.yaml", field)
    assert not (tmp_path / "t.png").exists()


@pytest.mark.parametrize(
    "text, field",
    [
        ("kind: stepping_stones\nlength: 9000\nsize: 0.05\ngap: 0.02\n", "size"),
        ("kind: rough\nlength: 9000\nwavelength: 0.01\namplitude: 0.02\n", "wavelength"),
    ],
)
def test_terrain_of_too_many_elements_is_refused(text, field, tmp_path, capsys):
    course = tmp_path / "many.yaml"
    course.write_text("name: many\n" + text)  # it took 24 GB before the OOM killer came
    assert main(["terrain", str(course)]) == 2
    _one_line_error(capsys, "many.yaml", field, "at most")


def test_a_large_course_draws_on_a_coarser_grid(tmp_path, capsys):
    from PIL import Image

    course = tmp_path / "long.yaml"
    course.write_text("name: long\nkind: flat\nx_min: 0\nlength: 2000\ny_min: -5\ny_max: 5\n")
    assert main(["terrain", str(course), "--png", str(tmp_path / "t.png")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert Image.open(tmp_path / "t.png").size[0] < 3000


# ------------------------------------------------------------------------------ robots
@pytest.mark.parametrize(
    "edit, expect",
    [
        (('lower="-0.6" upper="0.6"', 'lower="0.6" upper="-0.6"'), "swapped"),
        (('<mass value="0.001"/>', '<mass value="-1"/>'), "mass"),
        (('<mass value="2.240"/>', '<mass value="abc"/>'), "mass"),
        (('<mass value="2.240"/>', '<mass value="nan"/>'), "mass"),
        (('<box size="0.330 0.108 0.143"/>', '<box size=""/>'), "box size"),
        (
            (
                '<sphere radius="0.0103"/></geometry></collision>',
                '<sphere radius="x"/></geometry></collision>',
            ),
            "sphere radius",
        ),
    ],
)
def test_urdf_with_impossible_numbers_is_refused(edit, expect, tmp_path, capsys):
    text = LITTLEDOG_URDF.read_text()
    assert edit[0] in text
    urdf = tmp_path / "edited.urdf"
    urdf.write_text(text.replace(edit[0], edit[1]))  # every occurrence
    for command in (
        ["robot", str(urdf)],
        ["plan", "--robot", str(urdf), "--terrain", "flat", "--goal", "0.5,0"],
    ):
        assert main(command) == 2
        _one_line_error(capsys, "edited.urdf", expect)


def test_a_plan_whose_urdf_moved_names_the_fix(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    urdf = tmp_path / "mine" / "my_dog.urdf"
    urdf.parent.mkdir()
    shutil.copy(LITTLEDOG_URDF, urdf)
    d = json.loads(Path(path).read_text())
    d["robot"].update(name="my_dog", urdf=str(tmp_path / "gone" / "my_dog.urdf"))
    moved = tmp_path / "moved.json"
    moved.write_text(json.dumps(d))
    commands = [
        ["check", str(moved)],
        ["replay", str(moved), "--html", str(tmp_path / "r.html")],
        ["export", str(moved), "--out", str(tmp_path / "t.csv")],
        ["simulate", str(moved), "--out", str(tmp_path / "s.json")],
    ]
    for args in commands:
        assert main(args) == 2, args
        _one_line_error(capsys, "moved.json", "--robot")
    assert main(["check", str(moved), "--robot", str(urdf)]) == 0
    assert "OK" in capsys.readouterr().out
    assert main(["export", str(moved), "--robot", str(urdf), "--out", str(tmp_path / "t.csv")]) == 0
    # a URDF of another robot is refused, naming its joints
    assert main(["check", str(moved), "--robot", "solo12"]) == 2
    _one_line_error(capsys, "--robot solo12", "joints")


def test_plan_steps_first_is_a_feedback_option(short_flat_walk, capsys):
    path, _, _ = short_flat_walk
    assert main(["simulate", str(path), "--plan-steps-first", "--quiet"]) == 2
    _one_line_error(capsys, "--plan-steps-first", "--feedback")


# ------------------------------------------------------------------------------ check
def test_check_rejects_an_empty_plan(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    d = json.loads(Path(path).read_text())
    no_keyframes = tmp_path / "no_keyframes.json"
    no_keyframes.write_text(json.dumps(dict(d, keyframes=[])))
    one_sample = tmp_path / "one_sample.json"
    s = d["samples"]
    one_sample.write_text(json.dumps(dict(d, samples={k: v[:1] for k, v in s.items()})))
    for bad in (no_keyframes, one_sample):
        assert main(["check", str(bad)]) == 1
        out = capsys.readouterr().out
        assert "empty_plan" in out and "FAILED" in out, out


def test_check_prints_at_most_50_violations(short_flat_walk, tmp_path, capsys):
    path, _, _ = short_flat_walk
    d = json.loads(Path(path).read_text())
    for q in d["samples"]["q"]:
        q[2] -= 0.05  # every sample 5 cm into the ground
    sunk = tmp_path / "sunk.json"
    sunk.write_text(json.dumps(d))
    assert main(["check", str(sunk)]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 52 and "more violations" in lines[-2] and "FAILED" in lines[-1]
    total = int(re.search(r"FAILED, (\d+) violations", lines[-1]).group(1))
    assert total > 50  # more than printed
    assert main(["check", str(sunk), "--all"]) == 1
    assert len(capsys.readouterr().out.strip().splitlines()) == total + 1


# ------------------------------------------------------------------------------ signals
def _port_free(port):
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def test_sigterm_to_replay_stops_its_server(short_flat_walk):
    path, _, _ = short_flat_walk
    proc = subprocess.Popen(
        [sys.executable, "-m", "planner.cli.main", "replay", str(path), "--geometry", "collision"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        line = ""
        while "open http" not in line:
            assert time.monotonic() < deadline, "replay did not start"
            line = proc.stdout.readline()
            assert line or proc.poll() is None, proc.stderr.read()
        port = int(re.search(r":(\d+)/static", line).group(1))
        assert not _port_free(port)
        proc.send_signal(signal.SIGTERM)
        proc.wait(20)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 0, proc.stderr.read()
    # the server subprocess is gone and its port is free again
    time.sleep(0.5)
    assert _port_free(port)
    assert _running_in_session(proc.pid) == []  # nothing left of its session


def _start(args, **kw):
    """A ``stratawalk`` subprocess in its own session (so nothing it starts can escape)."""
    return subprocess.Popen(
        [sys.executable, "-m", "planner.cli.main", *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True, **kw,
    )  # fmt: skip


def _wait_for(predicate, proc, timeout_s, what):
    deadline = time.monotonic() + timeout_s
    while not predicate():
        assert proc.poll() is None, f"exited before {what}: {proc.communicate()}"
        assert time.monotonic() < deadline, f"no {what} within {timeout_s} s"
        time.sleep(0.1)


def _finish(proc, timeout_s=60):
    """Wait for ``proc`` (fail on a hang); its output; nothing of its session may remain."""
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"hung after the signals (killed after {timeout_s} s)")
    time.sleep(0.5)
    left = _running_in_session(proc.pid)
    if left:
        os.killpg(proc.pid, signal.SIGKILL)
    assert left == [], f"processes left behind: {left}"
    return out, err


def _running_in_session(sid):
    """Processes of session ``sid`` still running (exited ones, zombies, do not count)."""
    ps = subprocess.run(["ps", "-o", "pid=,stat=,args=", "-s", str(sid)], capture_output=True)
    rows = [line.split(None, 2) for line in ps.stdout.decode().splitlines() if line.strip()]
    return [row for row in rows if not row[1].startswith("Z")]


def test_two_ctrl_c_during_a_batch_keep_the_records(tmp_path):
    from planner.bench.batch import read_results

    scen = tmp_path / "scenarios.yaml"
    jobs = "".join(f"  - {{goal: [{0.3 + 0.02 * i:.2f}, 0.0]}}\n" for i in range(12))
    scen.write_text(
        "defaults: {terrain: flat, start: [0.2, 0.0], time_budget_s: 60}\njobs:\n" + jobs
    )
    out = tmp_path / "out"
    results = out / "results.jsonl"
    proc = _start(["batch", str(scen), "--out", str(out), "--workers", "2", "--quiet"])
    _wait_for(lambda: results.exists() and results.read_text().count("\n") >= 1, proc, 300,
              "a first record")  # fmt: skip
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = _finish(proc)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    records = read_results(results)  # every line whole and valid
    assert 1 <= len(records) < 12
    assert all(r["status"] == "ok" for r in records.values())


def test_sigterm_to_plan_saves_the_plan_so_far(tmp_path):
    from planner.planfile.plan import Plan
    from planner.planfile.validate import check_plan

    out = tmp_path / "partial.json"
    proc = _start(["plan", "--terrain", "flat", "--goal", "2.2,0", "--out", str(out)])
    seen = []

    def stepped():  # the progress bar shows steps taken
        seen.append(os.read(proc.stderr.fileno(), 4096).decode())
        return re.search(r"\b[1-9]\d* steps", "".join(seen)) is not None

    _wait_for(stepped, proc, 300, "a planned step")
    proc.send_signal(signal.SIGTERM)
    time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)  # a second one waits for the file
    text, err = _finish(proc)
    assert proc.returncode == 143, "".join(seen) + err
    assert "Traceback" not in err and "wrote" in text, text + err
    plan = Plan.load(out)
    assert "interrupted" in plan.outcome["message"] and not plan.outcome["reached_goal"]
    assert len(plan.keyframes) >= 2 and check_plan(plan).ok


def test_ctrl_c_during_simulate_keeps_the_motion(short_flat_walk, tmp_path):
    from planner.planfile.plan import Plan

    path, _, _ = short_flat_walk
    out = tmp_path / "exec.json"
    # 100x slower than planned: minutes of simulation, which runs faster than real time
    proc = _start(["simulate", str(path), "--time-scale", "100", "--out", str(out)])
    seen = []

    def simulating():  # the progress bar shows simulated time (a fixed sleep raced CI's pace)
        seen.append(os.read(proc.stderr.fileno(), 4096).decode())
        return re.search(r"simulated +[1-9]\d*\.\d s", "".join(seen)) is not None

    _wait_for(simulating, proc, 120, "simulated motion")
    proc.send_signal(signal.SIGINT)
    text, err = _finish(proc)
    assert proc.returncode == 130, text + err
    assert "interrupted" in text and "Traceback" not in err, text + err
    executed = Plan.load(out)
    assert len(executed.samples) > 10


def test_sigterm_to_bench_physics_stops_its_workers(tmp_path):
    """A stopped ``bench physics`` takes its pool's workers with it (killed with SIGTERM,
    the default handler ended the bench and left a spawned worker planning on for an
    hour) and writes its tables; exit 143."""
    out = tmp_path / "out"
    proc = _start(["bench", "physics", "--courses", "flat", "--modes", "open",
                   "--workers", "1", "--out", str(out)])  # fmt: skip

    def a_worker():  # the pool's spawned process, planning
        return any("multiprocessing" in row[2] for row in _running_in_session(proc.pid))

    _wait_for(a_worker, proc, 120, "a pool worker")
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    _, err = _finish(proc)
    assert proc.returncode == 143, err
    assert "Traceback" not in err, err
    assert (out / "physics.md").exists()


# ------------------------------------------------------------------------------ output locations
def _bad_location(where: str, tmp_path: Path) -> str:
    """A folder no file can be written into: under /proc, under /sys (where probing it is
    refused even to root), or a file in the way."""
    if where == "file":
        (tmp_path / "in_the_way").write_text("keep me")
        return str(tmp_path / "in_the_way" / "sub")
    if not Path(f"/{where}").is_dir():
        pytest.skip(f"no /{where} here")
    return f"/{where}/stratawalk-test"


@pytest.mark.parametrize("where", ["proc", "sys", "file"])
@pytest.mark.parametrize(
    "args, option",
    [
        (["plan", "--terrain", "flat", "--goal", "2.2,0", "--out", "{bad}/plan.json"], "--out"),
        (["export", "{plan}", "--out", "{bad}/t.csv"], "--out"),
        (["export", "{plan}", "--out", "{bad}/t.npz"], "--out"),
        (["export", "{plan}", "--out", "{bad}/t.bag"], "--out"),
        (["simulate", "{plan}", "--out", "{bad}/s.json"], "--out"),
        (["replay", "{plan}", "--html", "{bad}/r.html"], "--html"),
        (["plot", "{plan}", "--out", "{bad}/plots"], "--out"),
        (["terrain", "flat", "--png", "{bad}/t.png"], "--png"),
        (["generate-course", "--seed", "1", "--out", "{bad}/c.yaml"], "--out"),
        (["generate-course", "--seed", "1", "--out", "{tmp}/c.yaml", "--png", "{bad}/c.png"],
         "--png"),
        (["batch", "{scenarios}", "--out", "{bad}/batch"], "--out"),
        (["demo", "--out", "{bad}/demo"], "--out"),
        (["bench", "speed", "--out", "{bad}/bench"], "--out"),
    ],
)  # fmt: skip
def test_an_output_location_that_cannot_be_written_is_refused_first(
    args, option, where, short_flat_walk, tmp_path, capsys
):
    """One line naming the option, before any work (no progress bar: stderr is that line)."""
    bad = _bad_location(where, tmp_path)
    scenarios = Path(__file__).parents[1] / "examples" / "scenarios.yaml"
    fill = dict(bad=bad, plan=short_flat_walk[0], scenarios=scenarios, tmp=tmp_path)
    assert main([a.format(**fill) for a in args]) == 2
    err = _one_line_error(capsys, option)
    assert "cannot write into" in err or "is a file" in err, err
    assert "wrote" not in capsys.readouterr().out


def test_a_device_a_long_name_and_a_full_disk_are_refused_first(
    short_flat_walk, tmp_path, capsys, monkeypatch
):
    path = str(short_flat_walk[0])
    cases = [
        (["export", path, "--out", "/dev/null"], "not a regular file"),
        (["replay", path, "--html", str(tmp_path / ("x" * 300 + ".html"))], "too long"),
        (["plot", path, "--out", str(tmp_path / ("y" * 300))], "too long"),
    ]
    for args, expect in cases:
        assert main(args) == 2, args
        _one_line_error(capsys, expect)
    monkeypatch.setattr("planner.core.outputs.free_bytes", lambda folder: 300_000)
    for args in (
        ["plan", "--terrain", "flat", "--goal", "2.2,0", "--out", str(tmp_path / "p.json")],
        ["simulate", path, "--out", str(tmp_path / "s.json")],
        ["export", path, "--out", str(tmp_path / "t.csv")],
    ):
        assert main(args) == 2, args
        _one_line_error(capsys, "--out", "free on its disk")
    assert list(tmp_path.iterdir()) == []


def test_a_write_that_fails_after_the_work_keeps_the_result(
    short_flat_walk, tmp_path, capsys, monkeypatch
):
    """The folder becomes unwritable while the command works (here: a file takes its
    place): the plan, or the executed motion, is kept in the temporary folder, and the one
    line says where."""
    import tempfile

    import planner.planning.walk as walk
    import planner.sim.execution as execution
    from planner.planfile.loader import load_plan
    from planner.planfile.validate import check_plan

    safe = tmp_path / "safe"
    safe.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(safe))
    out = tmp_path / "out"

    def then_block(work):
        def wrapped(*a, **kw):
            result = work(*a, **kw)
            shutil.rmtree(out, ignore_errors=True)
            out.write_text("in the way")  # the folder is now a file
            return result

        return wrapped

    monkeypatch.setattr(walk, "plan_walk", then_block(walk.plan_walk))
    monkeypatch.setattr(execution, "simulate_plan", then_block(execution.simulate_plan))
    commands = [
        ["plan", "--terrain", "flat", "--goal", "0.3,0", "--quiet", "--out", str(out / "p.json")],
        ["simulate", str(short_flat_walk[0]), "--quiet", "--out", str(out / "s.json")],
    ]
    for args in commands:
        shutil.rmtree(out, ignore_errors=True)
        out.unlink(missing_ok=True)
        assert main(args) == 2, args
        err = _one_line_error(capsys, "--out", "cannot write it", "kept in")
        kept = Path(err.rsplit("kept in ", 1)[1])
        assert kept.parent == safe
        plan = load_plan(kept)  # whole, and a plan
        if args[0] == "plan":
            assert check_plan(plan).ok


def test_a_batch_whose_disk_fills_keeps_its_records(tmp_path):
    import errno

    from planner.bench.batch import _Writer, read_results
    from planner.core.errors import OutputError

    writer = _Writer(tmp_path / "results.jsonl", None)
    writer.write({"id": "a", "status": "ok"})

    class Full:
        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def close(self):
            raise OSError(errno.ENOSPC, "No space left on device")

    writer.fh.close()
    writer.fh = Full()
    with pytest.raises(OutputError, match=r"--out .*results.jsonl \(No space left on device\); "
                       r"the 1 records written now stay, rerun"):  # fmt: skip
        writer.write({"id": "b", "status": "ok"})
    writer.close()  # no second error
    assert list(read_results(tmp_path / "results.jsonl")) == ["a"]


# ------------------------------------------------------------------------------ plan loader
def _edited_plan(short_flat_walk, tmp_path, edit) -> Path:
    d = json.loads(Path(short_flat_walk[0]).read_text())
    if edit == "huge_base_x":
        d["samples"]["q"][5][0] = 1e300
    elif edit == "huge_keyframe_x":
        d["keyframes"][2]["base_position"][0] = 1e300
    elif edit == "reversed_times":
        d["samples"]["time"] = d["samples"]["time"][::-1]
    elif edit == "repeated_time":
        d["samples"]["time"][6] = d["samples"]["time"][5]
    elif edit == "huge_joint":
        d["samples"]["q"][3][9] = 1e6
    path = tmp_path / f"{edit}.json"
    path.write_text(json.dumps(d))
    return path


EDITS = ["huge_base_x", "huge_keyframe_x", "reversed_times", "repeated_time", "huge_joint"]


@pytest.mark.parametrize("edit", EDITS)
def test_every_command_refuses_a_plan_no_robot_could_execute(
    edit, short_flat_walk, tmp_path, capsys
):
    """One loader refuses them for every command; ``check`` reports them as violations."""
    bad = _edited_plan(short_flat_walk, tmp_path, edit)
    field = {"huge_base_x": "samples.q[5]", "huge_keyframe_x": "keyframes[2].base_position",
             "reversed_times": "samples.time", "repeated_time": "samples.time[6]",
             "huge_joint": "samples.q[3][7:]"}[edit]  # fmt: skip
    good = str(short_flat_walk[0])
    commands = [
        ["simulate", str(bad), "--quiet"],
        ["simulate", str(bad), "--feedback", "--quiet"],
        ["replay", str(bad), "--html", str(tmp_path / "r.html")],
        ["replay", good, "--compare", str(bad), "--html", str(tmp_path / "r.html")],
        ["plot", str(bad), "--out", str(tmp_path / "plots")],
        ["export", str(bad), "--out", str(tmp_path / "t.csv")],
    ]
    for args in commands:
        assert main(args) == 2, args
        _one_line_error(capsys, bad.name, field)
    assert sorted(p.name for p in tmp_path.iterdir()) == [bad.name]
    assert main(["check", str(bad)]) == 1
    out = capsys.readouterr().out
    kind = "time_order" if "time" in edit else "out_of_range"
    assert f": {kind}: {field}" in out and "FAILED" in out and "skipped" in out, out


# ------------------------------------------------------------------------------ export, replay
def test_export_refuses_a_rate_that_drops_samples_or_memory(short_flat_walk, tmp_path, capsys):
    from planner.planfile.export import load_trajectory

    path = str(short_flat_walk[0])
    out = tmp_path / "t.csv"
    assert main(["export", path, "--rate", "1e9", "--out", str(out)]) == 2  # was 54 GiB
    _one_line_error(capsys, "--rate 1e+09", "memory", "give --rate")
    assert main(["export", path, "--rate", "20", "--out", str(out)]) == 2
    err = _one_line_error(capsys, "--rate 20", "plan samples", "rad off", "--force")
    need = int(re.search(r"--rate (\d+) or more", err).group(1))
    assert not out.exists()
    assert main(["export", path, "--rate", "20", "--out", str(out), "--force"]) == 0
    warning = capsys.readouterr().err.strip()
    assert warning.startswith("stratawalk: warning: --rate 20") and warning.count("\n") == 0
    assert len(load_trajectory(out).t) == 47
    assert main(["export", path, "--rate", str(need), "--out", str(out)]) == 0  # every sample
    assert capsys.readouterr().err == ""


def test_replay_refuses_a_port_it_cannot_use(short_flat_walk, capsys):
    path = str(short_flat_walk[0])
    for port in ("99999", "0", "-5"):
        assert main(["replay", path, "--port", port, "--seconds", "0"]) == 2
        _one_line_error(capsys, f"--port {port}", "1..65535")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = str(busy.getsockname()[1])
        assert main(["replay", path, "--port", port, "--seconds", "0"]) == 2
        _one_line_error(capsys, f"--port {port}", "cannot listen")


def test_replay_prints_the_port_it_serves_on(short_flat_walk):
    with socket.socket() as s:  # a port free now
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = _start(["replay", str(short_flat_walk[0]), "--port", str(port), "--geometry",
                   "collision"])  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        line = ""
        while "open http" not in line:
            assert time.monotonic() < deadline, "replay did not start"
            line = proc.stdout.readline()
            assert line or proc.poll() is None, proc.stderr.read()
        assert f"http://127.0.0.1:{port}/static/" in line, line
        assert not _port_free(port)  # served there
        proc.send_signal(signal.SIGTERM)
        proc.wait(20)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


# ------------------------------------------------------------------------------ small ones
def test_goal_at_the_start_names_the_option(capsys):
    assert main(["plan", "--terrain", "flat", "--goal", "0.2,0", "--start", "0.2,0"]) == 2
    err = _one_line_error(capsys, "--goal 0.2,0", "--start")
    assert "Trajectory" not in err


def test_terrain_yaml_reads_numbers_without_a_signed_exponent(tmp_path, capsys):
    course = tmp_path / "c.yaml"
    course.write_text("name: c\nkind: flat\nlength: 1.0e9\n")
    assert main(["terrain", str(course)]) == 2  # a number (too long), not the string '1.0e9'
    _one_line_error(capsys, "length", "must be <= 10000")
    course.write_text("name: c\nkind: flat\nx_min: -5e-1\nlength: 2.5e0\n")
    assert main(["terrain", str(course)]) == 0
    assert "bounds (-0.5, 2.0," in capsys.readouterr().out
    course.write_text("name: c\nkind: flat\nlength: 2,5\n")
    assert main(["terrain", str(course)]) == 2
    _one_line_error(capsys, "length", "plain number")


def test_robot_given_a_folder_says_so(capsys):
    assert main(["robot", str(LITTLEDOG_URDF.parent)]) == 2
    _one_line_error(capsys, "is a folder", "littledog.urdf")


@pytest.mark.parametrize("command", [["bench", "courses"], ["bench", "physics"]])
def test_bench_workers_below_one_are_refused_in_one_line(command, tmp_path, capsys):
    """``--workers 0`` names the option, before any job starts."""
    args = [*command, "--workers", "0", "--out", str(tmp_path / "b")]
    assert main(args) == 2
    err = _one_line_error(capsys, "--workers")
    assert ">= 1" in err, err
