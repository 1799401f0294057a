"""The gait-queue driver (planner.planning.driver): its stop rules and its queue (8.2, 8.3).

A soft planner on flat ground makes the states, arrival moves and steps; the driver's
rules and counters are checked on them.
"""

import os
import signal
import time
from dataclasses import replace

import numpy as np
import pytest

from planner.body.robot import load_robot
from planner.core.interrupts import Interrupts
from planner.motion.gait_queue import CRAWL
from planner.motion.trajectory import Trajectory
from planner.planning.driver import GaitDriver, PlannedStates, QueueCycle, Run, StopRules, Walk
from planner.planning.recursive import RecursivePlanner
from planner.planning.soft import SoftPlanner
from planner.world.terrain import load_terrain

HL, FL, HR, FR = 2, 0, 3, 1


@pytest.fixture(scope="module")
def flat():
    """(planner, tau, start state): LittleDog on flat ground, its COM at (0.2, 0)."""
    planner = SoftPlanner(load_robot("littledog"), load_terrain("flat"))
    tau = Trajectory.straight((0.2, 0.0), (1.2, 0.0), planner.terrain, planner.com_height_m())
    return planner, tau, planner.initial_state((0.2, 0.0), tau)


def _driver(flat, goal=(1.2, 0.0), rules=None, source=PlannedStates):
    planner, tau, start = flat
    walk = Walk(planner, start)
    run = Run(np.asarray(goal, float), tau, time.perf_counter())
    return GaitDriver(planner, run, source(walk), rules, gait=CRAWL), walk


class CountedStates(PlannedStates):
    """The walk's states, counting how often the driver asks for one."""

    def __init__(self, walk):
        super().__init__(walk)
        self.asked = 0

    def state(self):
        self.asked += 1
        return super().state()


def test_the_planning_rules_stop_in_their_order(flat):
    """Nothing stops a fresh run 1 m from the goal (its distance is noted as progress);
    failures in a row, the time budget and max_cycles each stop it, the earlier rule's
    message winning where several hold."""
    planner = flat[0]
    st = planner.settings
    d, _ = _driver(flat)
    assert d.stop_reason() == ""
    assert d.run.best_dist_m == pytest.approx(1.0, abs=1e-3) and d.run.best_at == 0
    d.run.fails_in_row, d.run.last_failure = st.max_fails_in_row, "FL foot placement: x"
    assert d.stop_reason() == (
        f"stuck: {st.max_fails_in_row} failed step attempts in a row; last: FL foot placement: x"
    )
    d.run.t_begin -= st.time_budget_s + 1.0
    assert d.stop_reason() == f"stopped by the time budget ({st.time_budget_s:.0f} s)"
    d.run.cycles = st.max_cycles
    assert d.stop_reason() == f"stopped after {st.max_cycles} cycles (max_cycles)"


def test_no_progress_stops_after_the_patience_of_the_planner(flat):
    """``no_progress_cycles`` cycles without the COM 1 cm nearer; a recursive planner's
    cycle is ``attempts_per_cycle`` step attempts, so its patience is that many times
    longer."""
    planner = flat[0]
    d, _ = _driver(flat)
    patience = planner.settings.no_progress_cycles
    assert d.rules.patience_cycles == patience
    assert d.stop_reason() == "" and d.run.best_at == 0
    d.run.cycles = patience - 1
    assert d.stop_reason() == ""
    d.run.cycles = patience
    assert d.stop_reason().startswith(f"stuck: no progress in {patience} cycles")
    rec = RecursivePlanner(planner.robot, planner.terrain)
    rs = rec.recursion
    assert (
        StopRules.for_planning(rec).patience_cycles == patience * rs.attempts_per_cycle > patience
    )


def test_the_feedback_rules_have_no_time_budget_and_speak_of_the_measured_com(flat):
    planner = flat[0]
    st = planner.settings
    rules = StopRules.for_feedback(st, max_cycles=50, no_progress_cycles=16, max_arrivals=2)
    assert rules.time_budget_s is None and rules.progress_first and rules.measured
    d, _ = _driver(flat, rules=rules)
    d.run.t_begin -= 1e6
    assert d.stop_reason() == ""
    d.run.fails_in_row = st.max_fails_in_row
    assert d.stop_reason() == f"stuck: {st.max_fails_in_row} failed step attempts in a row"
    d.run.fails_in_row, d.run.cycles = 0, 16
    assert d.stop_reason() == "no progress in 16 cycles (COM 100 cm from goal)"


def _halted_stop_reason(d) -> str:
    """The driver's stop reason with a SIGTERM requested (the handlers restored after)."""
    old = {s: signal.getsignal(s) for s in Interrupts.SIGNALS}
    try:
        with Interrupts():
            os.kill(os.getpid(), signal.SIGTERM)
            return d.stop_reason()
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def test_progress_is_noted_before_a_halt_only_when_measured(flat):
    """``progress_first``: feedback notes the distance as measured before anything stops
    the run; planning notes it after the arrival, so not on a halt."""
    d, _ = _driver(flat)
    assert _halted_stop_reason(d) == "interrupted after 0 steps; the plan so far is kept"
    assert d.run.best_dist_m == np.inf
    d, _ = _driver(flat, rules=replace(d.rules, progress_first=True))
    assert _halted_stop_reason(d).startswith("interrupted")
    assert d.run.best_dist_m == pytest.approx(1.0, abs=1e-3)


def test_the_arrival_is_tried_once_per_keyframe_when_planning(flat):
    """A goal 2 cm ahead of the COM inside the feet: the arrival move is recorded in the
    walk (no cycle), and the rules go on from its end: the goal is reached. A goal 6 cm
    ahead whose arrival move fails is not tried again until the walk changes."""
    planner, _, start = flat
    com = planner.check.com_W(start)[:2]
    d, walk = _driver(flat, goal=com + [0.02, 0.0])
    assert d.stop_reason().startswith("reached the goal: COM 0.")
    assert d.run.arrivals == 1 and d.run.cycles == 0
    assert [p.phase for p in walk.parts] == ["arrival"]
    d, walk = _driver(flat, goal=com + [0.2, 0.0])  # ahead of the feet: no arrival
    assert d.stop_reason() == "" and d.run.arrival_tried == walk.n_keyframes == 1
    assert d.run.arrivals == 0 and walk.parts == []


def test_a_measured_arrival_is_a_cycle_and_the_rules_start_over(flat):
    """With ``max_arrivals`` (feedback): at most that many arrivals, each counted as a
    cycle, after which a new state is asked for before the goal test."""
    planner, _, start = flat
    com = planner.check.com_W(start)[:2]
    rules = StopRules.for_feedback(planner.settings, 50, 16, max_arrivals=1)
    d, walk = _driver(flat, goal=com + [0.06, 0.0], rules=rules, source=CountedStates)
    assert d.stop_reason().startswith("reached the goal: measured COM 0.")
    assert d.run.arrivals == 1 and d.run.cycles == 1 and d.source.asked == 2
    assert len(walk.parts) == 1
    d, walk = _driver(flat, goal=com + [0.06, 0.0], rules=replace(rules, max_arrivals=0))
    assert d.stop_reason() == "" and walk.parts == []  # 6 cm off: not within goal_tol_m


class Steps(QueueCycle):
    """Cycles whose steps are the planner's from the walk's state, or ``failed`` (its leg
    changed to the cycle's)."""

    def __init__(self, walk, failed=None):
        self.walk, self.failed, self.legs = walk, failed, []

    def attempt(self, driver, leg):
        self.legs.append(leg)
        if self.failed is not None:
            return replace(self.failed, leg=leg)
        p, state, tau = driver.planner, self.walk.state, driver.run.tau
        step = p.step(state, leg, tau, p.stride_at(state, leg, tau) * driver.step_scale[leg])
        self.walk.add(step)
        return step


def test_a_step_made_sends_its_leg_to_the_back(flat):
    d, walk = _driver(flat)
    hooks = Steps(walk)
    d.step_scale[HL] = 0.5
    d.run.fails_in_row = 3
    assert d.gait_cycle(hooks) == ""
    assert hooks.legs == [HL] and walk.steps == 1
    assert list(d.queue) == [FL, HR, FR, HL]
    assert d.step_scale[HL] == 1.0 and d.run.fails_in_row == 0 and d.run.cycles == 1


@pytest.fixture(scope="module")
def failed_placement(flat):
    """HL's step to a foothold 1 m ahead: its placement fails (Theta3)."""
    planner, tau, start = flat
    far = np.array([1.2, 0.1, 0.0])
    failed = planner.step(start, HL, tau, planner.stride_m(), target_W=far, try_others=False)
    assert not failed.ok and failed.phase == "foot_placement"
    return failed


def test_a_failed_placement_swaps_its_leg_and_halves_its_stride(flat, failed_placement):
    """Comment ii of 8.2: the failed leg goes after the next one, after n failures in a
    row n places back; its stride halves, down to ``min_step_fraction``. The failure is
    logged with its cycle, and is the stuck message's last failure."""
    planner = flat[0]
    d, walk = _driver(flat)
    hooks = Steps(walk, failed_placement)
    logged = len(planner.failures)
    d.gait_cycle(hooks)
    assert list(d.queue) == [FL, HL, HR, FR]
    assert d.step_scale[HL] == 0.5 and d.run.fails_in_row == 1
    assert d.run.last_failure.startswith("HL foot placement: Theta3")
    assert planner.failures[logged]["cycle"] == 1 and planner.failures[logged]["leg"] == "HL"
    d.gait_cycle(hooks)  # FL fails too: two places back
    assert list(d.queue) == [HL, HR, FL, FR] and d.run.fails_in_row == 2
    d.step_scale[HL] = 0.3
    d.gait_cycle(hooks)  # HL again: three places back, its stride at the least
    assert list(d.queue) == [HR, FL, FR, HL] and d.run.cycles == 3
    assert d.step_scale[HL] == planner.settings.min_step_fraction == 0.25
    assert hooks.legs == [HL, FL, HL] and walk.parts == []


def test_a_fixed_sequence_sends_a_failed_leg_to_the_back(flat, failed_placement):
    """8.1's sequence S (hard persuasion): a failed leg waits a whole cycle."""
    d, walk = _driver(flat)
    hooks = Steps(walk, failed_placement)
    hooks.fixed_sequence = True
    d.gait_cycle(hooks)
    assert list(d.queue) == [FL, HR, FR, HL] and d.run.fails_in_row == 1


def test_drive_runs_cycles_until_a_rule_or_the_cycle_stops(flat):
    st = flat[0].settings
    d, _ = _driver(flat)
    calls = []

    def cycle(driver):
        calls.append(driver.run.cycles)
        driver.run.cycles += 1
        return "done" if len(calls) == 3 else ""

    assert d.drive(cycle) == "done" and calls == [0, 1, 2]
    d.run.cycles = st.max_cycles
    assert d.drive(cycle) == f"stopped after {st.max_cycles} cycles (max_cycles)"
    assert len(calls) == 3


def test_a_soft_plan_counts_every_attempt_as_a_cycle(flat):
    """The soft planner on the driver: a short flat walk, one cycle per step, no failure."""
    planner = SoftPlanner(flat[0].robot, flat[0].terrain)
    plan = planner.plan((0.2, 0.0), (0.45, 0.0))
    assert plan.reached_goal, plan.message
    assert plan.stats["cycles"] == plan.stats["steps"] >= 4 and plan.stats["failures"] == []
    # a step of a full stride brings the COM more than PROGRESS_M nearer: no stall longer
    # than the crawl's four steps (a leg's step may leave the COM where it was)
    assert 1 <= plan.stats["longest_stall_cycles"] <= 4
