"""Fixed-rate trajectory export (planner.planfile.export) against the plan and in MuJoCo."""

import numpy as np
import pytest

from planner.cli.main import main
from planner.planfile.export import export_plan, load_trajectory, plan_from_trajectory
from planner.planfile.plan import Plan, Samples
from planner.planning.walk import plan_walk
from planner.sim.simulate import cycle_starts, run_open_loop


@pytest.fixture(scope="module")
def plan():
    p, report = plan_walk("littledog", "step5cm", goal_xy=(0.5, 0.0))
    assert report.ok
    return p


@pytest.fixture(scope="module")
def csv_traj(plan, tmp_path_factory):
    folder = tmp_path_factory.mktemp("export")
    src = plan.save(folder / "plan.json")
    out = folder / "plan.csv"
    assert main(["export", str(src), "--rate", "500", "--out", str(out)]) == 0
    return load_trajectory(out)


def test_rows_reproduce_the_plan_samples_at_their_times(plan, csv_traj):
    tr, s = csv_traj, plan.samples
    assert np.allclose(np.diff(tr.t)[:-1], 1 / 500, atol=1e-12) and tr.t[-1] == s.time[-1]
    i = np.clip(np.searchsorted(tr.t, s.time, side="right") - 1, 0, len(tr.t) - 1)
    dt = (s.time - tr.t[i])[:, None]
    robot = plan.load_robot()
    joints = [leg.q_index + k for leg in robot.legs for k in range(3)]
    assert np.abs(tr.q[i] + dt * tr.dq[i] - s.q[:, joints]).max() < 1e-6
    assert np.abs(tr.base_pos[i] + dt * tr.base_vel[i] - s.q[:, :3]).max() < 1e-6
    # velocities are the rows' own finite differences where no sample lies between them
    fd = np.diff(tr.q, axis=0) / np.diff(tr.t)[:, None]
    smooth = np.searchsorted(s.time, tr.t[:-1], side="right") == np.searchsorted(
        s.time, tr.t[1:], side="left"
    )
    assert np.abs(fd[smooth] - tr.dq[:-1][smooth]).max() < 1e-6
    # stance rows: the planned forces carry the weight and no swing foot carries any
    weight = robot.total_mass_kg * 9.81
    assert np.allclose(tr.forces[:, :, 2].sum(axis=1), weight, rtol=1e-3)
    assert np.abs(tr.forces[~tr.contact]).max() < 1e-6 * weight
    assert (tr.contact.sum(axis=1) >= 3).all() and (tr.contact.sum(axis=1) == 3).any()


def test_npz_and_csv_hold_the_same_rows(plan, csv_traj, tmp_path):
    out = export_plan(plan, 500.0).save(tmp_path / "p.npz")
    npz = load_trajectory(out)
    assert npz.columns() == csv_traj.columns() and len(npz.columns()) == 66
    np.testing.assert_array_equal(npz.table(), csv_traj.table())


def test_the_executor_runs_an_export_as_it_runs_the_plan(plan, csv_traj):
    end = cycle_starts(plan.samples.contact)[4] + 1
    short = Plan.from_dict(plan.to_dict(), source=plan.source)
    s = plan.samples
    short.samples = Samples(s.time[:end].copy(), s.q[:end].copy(), s.contact[:end].copy())
    m_plan = run_open_loop(short).metrics
    rows = csv_traj.t <= s.time[end - 1] + 1e-12
    traj = csv_traj
    for name in ("t", "base_pos", "base_quat", "q", "contact", "torque_ff"):
        setattr(traj, name, getattr(csv_traj, name)[rows])
    m_traj = run_open_loop(plan_from_trajectory(short, traj), None, traj.torque_ff).metrics
    assert m_plan.ok and m_traj.ok, (m_plan.summary(), m_traj.summary())
    assert abs(m_plan.final_error_m - m_traj.final_error_m) < 0.003


@pytest.mark.parametrize(
    "args, expect",
    [
        (["--rate", "-5", "--out", "{d}/a.csv"], "--rate: must be a number"),
        (["--rate", "500", "--out", "{d}/a.txt"], "ending in .csv or .npz"),
        (["--rate", "500", "--out", "{d}"], "is a folder"),
    ],
)
def test_bad_export_options_are_one_line(plan, tmp_path, capsys, args, expect):
    src = plan.save(tmp_path / "plan.json")
    rc = main(["export", str(src), *[a.format(d=tmp_path) for a in args]])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.count("\n") == 0 and expect in err, err
