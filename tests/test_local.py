"""The gait step queue and the soft-persuasion local planner of section 8.2."""

import numpy as np
import pinocchio as pin
import pytest

from planner.local.gait_queue import CRAWL, GaitQueue
from planner.local.soft import SoftPlanner
from planner.robot import load_robot
from planner.terrain import load_terrain


def test_queue_pop_push_swap():
    q = GaitQueue(CRAWL)  # HL, FL, HR, FR
    assert q.pop() == 2
    q.push(2)  # stepped: to the back
    assert list(q) == [0, 3, 1, 2]
    leg = q.pop()  # FL fails ...
    q.swap(leg)  # ... the next leg goes first, FL right after it
    assert list(q) == [3, 0, 1, 2]
    with pytest.raises(ValueError):
        GaitQueue([0, 5])


@pytest.fixture(scope="module")
def flat_planner():
    return SoftPlanner(load_robot("littledog"), load_terrain("flat"))


def test_short_flat_walk_reaches_goal_on_the_leaves(flat_planner):
    planner = flat_planner
    plan = planner.plan([0.2, 0.0], [0.45, 0.0])
    assert plan.reached_goal, plan.message
    assert plan.distance_to_goal_m <= planner.settings.goal_tol_m
    assert plan.stats["steps"] >= 4
    # independent check with Pinocchio: stance feet never move between consecutive samples
    robot = planner.robot
    model, data = robot.model, robot.model.createData()
    fids = [model.getFrameId(f) for f in robot.foot_frames]

    def centres(s):
        q = robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad)
        pin.framesForwardKinematics(model, data, q)
        return np.array([data.oMf[f].translation for f in fids])

    prev = centres(plan.samples[0])
    for a, b in zip(plan.samples[:-1], plan.samples[1:], strict=True):
        cur = centres(b)
        both = a.in_contact & b.in_contact
        assert np.max(np.linalg.norm(cur[both] - prev[both], axis=1)) < 1e-6
        assert b.in_contact.sum() >= 3
        prev = cur
    assert np.all(np.diff(plan.times) > 0)


def test_failed_step_is_retried_from_the_queue(flat_planner, monkeypatch):
    planner = SoftPlanner(flat_planner.robot, flat_planner.terrain)
    attempts = []
    real_swing = planner.swing
    failed = {"FL": False}

    def swing(state, leg, tau, step_m, target=None):
        attempts.append(leg)
        sol, path = real_swing(state, leg, tau, step_m, target)
        if leg == 0 and not failed["FL"]:  # force the first FL placement to fail
            failed["FL"] = True
            sol.feasible = False
            sol.diagnosis = "forced failure"
            return sol, []
        return sol, path

    monkeypatch.setattr(planner, "swing", swing)
    planner.settings.max_cycles = 6
    planner.plan([0.2, 0.0], [1.0, 0.0])
    # crawl HL, FL (fails), then HR goes first and FL is retried right after it
    assert attempts[:4] == [2, 0, 3, 0]
