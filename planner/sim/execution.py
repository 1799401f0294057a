"""Feedback from a measured state (paper 8.3) and precompute-then-correct (8.4).

A :class:`StateSource` measures the robot: base pose, joint angles and which feet touch
(on LittleDog: motion capture and joint encoders). :class:`SimulatedMocap` stands in for
it with the MuJoCo simulator of :mod:`planner.sim.simulate`, optionally with Gaussian noise
and a latency.

The modes behind one call, :func:`simulate_plan`, and the ``stratawalk simulate``
command are here too (this module uses :mod:`planner.sim.simulate`, never the reverse).

Feedback (8.3), :func:`run_feedback`: every cycle (one gait step) the soft-persuasion
planner of 8.2 starts from the *measured* configuration: measured base pose and joints,
the stance feet where the robot's feet actually are (projected onto the terrain), and
plans the next step from there (Theta2 body move, Theta3 foothold), which the simulator
then executes. The cycles, the gait queue, its failure handling and the stop rules are
the planners' driver's (:class:`planner.planning.driver.GaitDriver`), its states
measured (:class:`MeasuredStates`), its cycle following the precomputed plan
(:class:`PlanFollowing`). Slip, rolling of the feet and servo compliance do not
accumulate: each step starts from the truth.

Precompute-then-correct (8.4), :func:`run_corrected`: the precomputed plan is executed
cycle by cycle; at each cycle start the measured foot centres are compared with the
plan's, the cycle's base path is shifted by their mean offset (the body keeps its planned
place relative to its support, so the centre of mass stays where the plan balanced it),
the stance feet are held where they are, the swing foot blends from where it is to its
planned (world) foothold, and the set-points are re-solved by Paden-Kahan leg IK
(:mod:`planner.body.kinematics`). Footholds return to the plan's, so errors stay bounded.

:func:`shift_body` moves a plan's body against its feet (IK again): a plan perturbed on
purpose, to check that the simulator notices a centre of mass outside the support.
"""

from __future__ import annotations

import math
import sys
import time as _time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from planner.core.errors import InputError
from planner.planfile.plan import Plan, Samples, states_of_samples
from planner.planning.driver import QueueCycle
from planner.sim.simulate import (
    SimResult,
    SimSettings,
    Simulator,
    cycle_starts,
    finish_run,
    new_run,
    reporting_progress,
    run_open_loop,
)

__all__ = [
    "Measurement",
    "MeasuredStates",
    "PlanFollowing",
    "SimulatedMocap",
    "StateSource",
    "blend_in",
    "correct_cycle",
    "measured_state",
    "run_corrected",
    "run_feedback",
    "shift_body",
    "simulate_plan",
    "cmd_simulate",
]

_Array = NDArray[np.float64]


@dataclass
class Measurement:
    """A measured configuration: time [s], Pinocchio ``q`` (19,), feet touching (4,)."""

    time_s: float
    q: _Array
    contact: NDArray[np.bool_]


class StateSource(Protocol):
    """What feedback needs from the robot: its measured configuration (section 8.3)."""

    def measure(self) -> Measurement:
        """The latest available measurement."""


class SimulatedMocap:
    """The simulator as motion capture plus joint encoders, with noise and latency.

    Base position noise ``position_noise_m`` (per axis), base orientation noise
    ``angle_noise_rad`` (a random rotation vector per axis), joint noise
    ``joint_noise_rad``, all Gaussian; ``latency_s``: the measurement returned is the
    configuration that many seconds old (from the simulator's history, recorded every
    control tick).
    """

    def __init__(
        self,
        sim: Simulator,
        position_noise_m: float = 0.0,
        angle_noise_rad: float = 0.0,
        joint_noise_rad: float = 0.0,
        latency_s: float = 0.0,
        seed: int = 0,
    ):
        for name, v in (
            ("position_noise_m", position_noise_m),
            ("angle_noise_rad", angle_noise_rad),
            ("joint_noise_rad", joint_noise_rad),
            ("latency_s", latency_s),
        ):
            if not (math.isfinite(v) and v >= 0.0):
                raise InputError(f"simulate: {name} must be a number >= 0, got {v!r}")
        self.sim = sim
        self.position_noise_m = position_noise_m
        self.angle_noise_rad = angle_noise_rad
        self.joint_noise_rad = joint_noise_rad
        self.latency_s = latency_s
        self.rng = np.random.default_rng(seed)
        if latency_s > 0.0:
            sim.history_s = max(sim.history_s, latency_s)

    def measure(self) -> Measurement:
        """The simulator's configuration ``latency_s`` ago, with noise."""
        sim = self.sim
        if self.latency_s > 0.0 and sim.history:
            want = sim.time - self.latency_s
            older = [h for h in sim.history if h[0] <= want + 1e-9]
            t, q, contact = older[-1] if older else sim.history[0]
            q, contact = q.copy(), contact.copy()
        else:
            t, q, contact = sim.time, sim.q(), sim.touches().feet
        q[:3] += self.rng.normal(0.0, self.position_noise_m, 3) if self.position_noise_m else 0.0
        if self.angle_noise_rad:
            import pinocchio as pin

            R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
            R = pin.exp3(self.rng.normal(0.0, self.angle_noise_rad, 3)) @ R
            qq = pin.Quaternion(R)
            q[3:7] = [qq.x, qq.y, qq.z, qq.w]
        if self.joint_noise_rad:
            q[7:] += self.rng.normal(0.0, self.joint_noise_rad, len(q) - 7)
        return Measurement(float(t), q, np.asarray(contact, bool))


def _foot_centres(robot, q: _Array) -> _Array:
    """(4, 3) foot sphere centres of a Pinocchio configuration."""
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import rotation_from_quat

    kin = kinematics_of(robot)
    return kin.feet_W(q[:3], rotation_from_quat(q[3:7]), robot.joints_from_q(q))


def measured_state(robot, terrain, meas: Measurement):
    """The planner's :class:`~planner.body.state.State` of a measurement (section 8.3).

    Base pose and joints as measured; every foot taken as a stance foot (a cycle starts
    on S0) at the contact point under its measured sphere centre, put on the terrain the
    planner sees (``terrain.height``), so that the Theta problems start on a leaf.
    """
    from planner.body.contact import contact_from_foot_centre
    from planner.body.state import State
    from planner.core.lie import rotation_from_quat

    q = meas.q
    centres = _foot_centres(robot, q)
    feet = contact_from_foot_centre(terrain, centres, robot.foot_radius_m)
    feet[:, 2] = np.asarray(terrain.height(feet[:, 0], feet[:, 1]), float)
    return State(
        base_position_W=q[:3].copy(),
        base_rotation_W=rotation_from_quat(q[3:7] / np.linalg.norm(q[3:7])),
        feet_W=feet,
        joints_rad=robot.joints_from_q(q),
        stratum=0,
        support=(0, 1, 2, 3),
        info={"measured_at_s": meas.time_s},
    )


def _source(sim: Simulator, source: StateSource | None, **noise) -> StateSource:
    return source if source is not None else SimulatedMocap(sim, **noise)


# ------------------------------------------------------------------------------ 8.3
# (stride fraction, Lambda_c shrink) tried in turn for one step from a measured state
BACKOFF = ((1.0, None), (0.5, 0.5), (0.25, 0.7))
GUIDE_FAILS = 2  # failed cycles in a row after which feedback stops following the plan's steps
# a corrected swing sample whose IK joints leave the plan's by more than this [rad] keeps
# the plan's (step10cm's recursive plan: HR's corrected knee 66 degrees off, the foot on
# the step edge, a fall)
SWING_JUMP_RAD = 0.35
# a corrected cycle whose feet leave their legs' reach (a stance foot measured a few
# millimetres off a plan that has the leg stretched: barrier9cm's recursive plan, HR at its
# reach limit) has its body moved toward them by the worst sample's miss, up to this far
# in all [m], in at most REACH_SHIFTS rounds (correct_cycle); the gates of
# _follow_corrected (balance, leg links, path checks) judge the shifted samples
REACH_SHIFT_M = 0.01
REACH_SHIFTS = 3
REPLANS = 2  # ... and re-plans the rest of the walk from the measured state, at most so often
REPLAN_BUDGET_S = 120.0  # planning time of one such re-plan [s] (the robot stands on four feet)
MAX_ARRIVALS = 2  # arrival moves (four feet, COM over the goal) tried from measured states


def _step_keyframes(plan: Plan) -> list[tuple[int, int, int]]:
    """(swing keyframe, 0-based leg, keyframe with the leg down again) of each step."""
    kfs = plan.keyframes
    out = []
    for k, kf in enumerate(kfs[:-1]):
        leg = int(kf.stratum) - 1
        if leg < 0:
            continue
        nxt = next((j for j in range(k + 1, len(kfs)) if leg + 1 in kfs[j].support), None)
        if nxt is not None:
            out.append((k, leg, nxt))
    return out


def planned_steps(plan: Plan) -> list[tuple[int, _Array]]:
    """The plan's steps in order: (0-based leg, the terrain point it lands on, world [m]).

    A swing keyframe (stratum i = leg + 1) is followed by the keyframe that has the leg
    down again; its contact point there is the foothold.
    """
    kfs = plan.keyframes
    return [
        (leg, np.asarray(kfs[j].feet[leg], float).copy()) for _, leg, j in _step_keyframes(plan)
    ]


def planned_knees(plan: Plan) -> list[int]:
    """The knee branch each of the plan's steps lands on, aligned with :func:`planned_steps`.

    +1 forward, -1 rearward (:meth:`planner.body.kinematics.LegKinematics.knee_direction`) in
    the keyframe that has the leg down again. The feedback's steps land on the plan's
    branch: where a knee's choice (:meth:`LocalPlanner._other_knee_landing`) is close, a
    state a few millimetres off the plan's flips it, and the plan's next steps, found
    with the plan's branch, then find no body move.
    """
    from planner.body.kinematics import kinematics_of

    kin = kinematics_of(plan.load_robot())
    states = plan.keyframe_states()
    return [
        kin.knee_direction(leg, states[j].joints_rad[leg]) for _, leg, j in _step_keyframes(plan)
    ]


def planned_body_poses(plan: Plan) -> list:
    """The body pose each of the plan's steps swings from, aligned with :func:`planned_steps`.

    The swing keyframe's :class:`~planner.body.state.State` (its base is where the step's body
    move ended), the swinging foot put back where it lifts from (the keyframe has it in
    the air): the feedback re-planner's hint for Theta2 (8.3 with 8.4's plan).
    """
    states = plan.keyframe_states()
    out = []
    for k, kf in enumerate(plan.keyframes[:-1]):
        leg = int(kf.stratum) - 1
        if leg >= 0 and any(leg + 1 in f.support for f in plan.keyframes[k + 1 :]):
            pose = states[k]
            before = next((f for f in plan.keyframes[k::-1] if leg + 1 in f.support), None)
            if before is not None:
                pose.feet_W = np.array(pose.feet_W, float)
                pose.feet_W[leg] = np.asarray(before.feet[leg], float)
            out.append(pose)
    return out


def replan_rest(robot, terrain, mu, settings, state, goal_xy, tau):
    """A new plan of the rest of the walk from a measured ``state`` (8.3), or None.

    When the precomputed plan's steps no longer fit the measured state (barrier75mm: the
    robot 1 cm off the plan's pose beside the barrier, a knee near its limit), the soft
    planner (8.2, with its look-ahead and retrace) plans from there to the goal within
    ``REPLAN_BUDGET_S``; where it stalls, the recursive planner (8.5, which traces back
    and tries shorter strides) gets the same budget. Its steps become the guide. None
    when neither reaches the goal: barrier9cm's two re-plans stopped after 7 and 12
    steps, followed into their dead end, where the gait queue's greedy steps from the
    measured state reach the goal.
    """
    from dataclasses import replace

    from planner.planning.recursive import RecursivePlanner
    from planner.planning.soft import SoftPlanner
    from planner.planning.walk import plan_of

    budget = replace(settings, time_budget_s=REPLAN_BUDGET_S)
    start_xy = state.base_position_W[:2]
    for kind in (SoftPlanner, RecursivePlanner):
        local = kind(robot, terrain, mu=mu, settings=budget)
        res = local.plan(start_xy, goal_xy, tau=tau, start_state=state)
        if res.reached_goal and res.stats["steps"] > 0:
            return plan_of(robot, terrain, mu, start_xy, goal_xy, res, {})
    return None


def plan_step_cycles(plan: Plan) -> list[tuple[int, int]] | None:
    """Sample ranges (a, b) of the plan's steps, aligned with :func:`planned_steps`.

    Step j runs from the touchdown that ends step j-1 (sample 0 for the first) to its own
    touchdown, so it holds the body moves before its swing. None when the samples' swings
    do not match the keyframes' (a plan edited by hand).
    """
    s = plan.samples
    allc = s.contact.all(axis=1)
    out, a, k = [], 0, 1
    legs = []
    while k < len(allc):
        if allc[k - 1] and not allc[k]:
            up = np.flatnonzero(~s.contact[k])
            down = np.flatnonzero(allc[k:])
            if len(up) != 1 or not down.size:
                return None
            b = k + int(down[0])
            out.append((a, b))
            legs.append(int(up[0]))
            a, k = b, b + 1
        else:
            k += 1
    return out if legs == [leg for leg, _ in planned_steps(plan)] else None


def _queue_after(gait, leg: int):
    """A gait queue whose front is the leg after ``leg`` in ``gait``'s order."""
    from planner.motion.gait_queue import GaitQueue

    order = [int(i) for i in gait]
    k = order.index(int(leg)) if int(leg) in order else -1
    return GaitQueue(order[k + 1 :] + order[: k + 1])


def run_feedback(
    plan: Plan,
    settings: SimSettings | None = None,
    source: StateSource | None = None,
    local_settings=None,
    max_cycles: int | None = None,
    no_progress_cycles: int = 16,
    correct_plan_steps: bool = True,
    plan_steps_first: bool = False,
    **noise,
) -> SimResult:
    """Walk to the plan's goal step by step from the measured state (8.3, with 8.4).

    The gait-queue driver of 8.2 (:class:`planner.planning.driver.GaitDriver`) with the
    soft planner (``local_settings``, default: the plan's) runs cycles from the robot as
    measured (:class:`MeasuredStates`), each step executed in the simulator at once. Its
    cycles follow the plan's steps, correct them (8.4) and plan the rest anew
    (:class:`PlanFollowing`). Measurements come from ``source`` (default:
    :class:`SimulatedMocap` of the simulator with ``noise``: position_noise_m,
    angle_noise_rad, joint_noise_rad, latency_s, seed). Stops at the goal, after
    ``max_cycles`` (default: twice the plan's cycles plus 20), after ``max_fails_in_row``
    failed cycles in a row, when the COM has not come 1 cm closer to the goal in
    ``no_progress_cycles`` cycles (:meth:`planner.planning.driver.StopRules.for_feedback`),
    or on a fall.
    """
    from planner.motion.trajectory import Trajectory
    from planner.planning.driver import GaitDriver, Run, StopRules
    from planner.planning.soft import SoftPlanner

    wall0 = _time.perf_counter()
    sim, ex = new_run(plan, settings, "feedback")
    t0 = sim.time
    src = _source(sim, source, **noise)
    robot, terrain = plan.load_robot(), plan.load_terrain()
    st = local_settings or _planned_settings(plan)
    local = SoftPlanner(robot, terrain, mu=plan.friction, settings=st)
    tau = Trajectory.straight(plan.start[:2], plan.goal[:2], terrain, local.com_height_m())
    n_plan = max(len(cycle_starts(plan.samples.contact)), 1)
    max_cycles = max_cycles if max_cycles is not None else 2 * n_plan + 20
    states = MeasuredStates(src, robot, terrain, ex, local)
    rules = StopRules.for_feedback(st, max_cycles, no_progress_cycles, MAX_ARRIVALS)
    driver = GaitDriver(local, Run(plan.goal[:2], tau, wall0), states, rules, gait=st.gait)
    follow = PlanFollowing(
        plan, states, st, no_progress_cycles, correct_plan_steps, plan_steps_first
    )
    m = ex.monitor.metrics
    try:
        message = driver.drive(follow)
    except KeyboardInterrupt:
        ex.interrupt()
        message = m.message
    m.message = message
    extra = {
        "feedback": {
            "steps": follow.steps,
            "cycles": driver.run.cycles,
            "plan_steps": len(follow.guide),
            "plan_steps_followed": follow.followed,  # landed on the plan's foothold
            "plan_steps_corrected": follow.corrected,  # the plan's own step, corrected (8.4)
            "replans": follow.replans,  # steps of each re-plan of the rest (0: it did not reach)
            "arrivals": driver.run.arrivals,  # arrival moves executed (four feet, COM over goal)
            "planner_solves": local.stats,
            "planner_failures": local.failures[-50:],
        }
    }
    return finish_run(plan, ex, wall0, t0, extra)


def _fell(ex) -> str:
    """The stop message of a fall."""
    m = ex.monitor.metrics
    return f"fell at {m.fall_time_s:.1f} s ({m.fall_reason})"


class MeasuredStates:
    """The driver's source of states in feedback (8.3): the robot as measured.

    Every :meth:`state` is a new measurement of ``source`` (:func:`measured_state`), the
    last kept in ``meas`` and ``last`` for the cycle planned from it; moves are executed
    in the simulator of the run ``ex`` at the planner's (``local``) time law.
    """

    def __init__(self, source: StateSource, robot, terrain, ex, local):
        self.source, self.robot, self.terrain = source, robot, terrain
        self.ex, self.sim, self.local = ex, ex.sim, local
        self.meas: Measurement | None = None
        self.last = None

    def state(self):
        """A new measurement's state."""
        self.meas = self.source.measure()
        self.last = measured_state(self.robot, self.terrain, self.meas)
        return self.last

    def stamp(self) -> float:
        """The last measurement's time [s]."""
        return self.meas.time_s

    def halted(self) -> str:
        """The robot fell."""
        return _fell(self.ex) if self.ex.stopped else ""

    def arrive(self, end, path: list) -> str:
        """Execute an arrival move (four feet, the COM over the goal)."""
        times = np.concatenate([[0.0], self.local.body_offsets_s(path)])
        return self.execute(path, times)

    def execute(self, path: list, times: _Array) -> str:
        """Follow planned states ``path`` at ``times``; "" or the fall's message."""
        return "" if _execute(self.ex, self.robot, self.sim, path, times) else _fell(self.ex)


class PlanFollowing(QueueCycle):
    """Feedback's cycle (8.3 with 8.4): the precomputed plan's steps from measured states.

    The driver's leg is the plan's next step's (:func:`planned_steps`) while there is
    one, else the gait queue's. Its step is planned from the measured state
    (:meth:`attempt`): onto the plan's foothold (the body nearer the support's incentre
    at each ``BACKOFF``, Theta2 started from the plan's body pose, the plan's knee
    branch), else with Lambda_t's stride; where none is found the plan's own step is
    executed, corrected as in 8.4 (:func:`_follow_corrected`, its gates passed), first
    with ``plan_steps_first``. After ``GUIDE_FAILS`` failed cycles in a row, or a failure
    after half of ``no_progress_cycles`` without progress, the rest of the walk is
    planned anew (:func:`replan_rest`, at most ``REPLANS`` times) and followed when it
    reaches the goal; else, or past the plan's last step, the gait queue and Lambda_t
    take over. Every step is executed once made (:meth:`after`).
    """

    def __init__(self, plan: Plan, states: MeasuredStates, settings, no_progress_cycles: int,
                 correct_plan_steps: bool = True, plan_steps_first: bool = False):  # fmt: skip
        self.plan, self.states, self.st = plan, states, settings
        self.local, self.ex = states.local, states.ex
        self.no_progress_cycles = no_progress_cycles
        self.correct_plan_steps = correct_plan_steps
        self.plan_steps_first = plan_steps_first
        self.follow(plan)
        self.steps = self.followed = self.corrected = 0
        self.replanned_at = 0  # the cycle of the last re-plan
        self.replans: list[int] = []  # the re-plans made (8.3): their steps, reaching or not
        self.guided = self.on_plan = False  # this cycle's leg is the plan's; on its foothold
        self.ran: bool | None = None  # this cycle executed the plan's step, corrected: upright

    def follow(self, plan: Plan) -> None:
        """Follow ``plan``'s steps from its first (the guide)."""
        self.guide, self.poses = planned_steps(plan), planned_body_poses(plan)
        self.knees = planned_knees(plan)
        self.ranges = plan_step_cycles(plan) if self.correct_plan_steps else None
        self.samples, self.centres, self.g = plan.samples, plan.foot_centres_W(), 0

    def leg(self, driver) -> int:
        """The guide's next step's leg, else the queue's front."""
        self.guided = self.g < len(self.guide)
        return self.guide[self.g][0] if self.guided else driver.queue.pop()

    def corrected_step(self, g: int, balance_m=None, refused=None):
        """The guide's step g, corrected from the measurement and executed, or None (8.4)."""
        a, b = self.ranges[g]
        return _follow_corrected(
            self.ex, self.states.meas, self.states.robot, self.states.terrain, self.samples,
            self.centres, a, b, self.ex.sim, self.local, refused, balance_m,
        )  # fmt: skip

    def attempt(self, driver, leg: int):
        """The cycle's step from the measured state; None: the plan's own step was executed."""
        local, state, g, cycle = self.local, self.states.last, self.g, driver.run.cycles
        step, self.on_plan, self.ran = None, False, None
        # the plan's own step, corrected from the measured state (8.4), where its gates
        # pass: first with plan_steps_first (the plan's body poses were looked ahead),
        # else where no step planned anew reaches the plan's foothold
        may_correct = self.guided and self.ranges is not None
        if may_correct and self.plan_steps_first:
            refused: list[str] = []
            self.ran = self.corrected_step(g, refused=refused)
            if refused:
                local._log_failure(cycle, leg, "corrected_step", state, refused[-1])
        if self.guided and self.ran is None:  # the plan's foothold, the body ever more centred
            for _, shrink in BACKOFF:
                step = local.step(
                    state, leg, driver.run.tau, local.stride_m(), shrink, self.guide[g][1],
                    False, body_hint=self.poses[g], knee=self.knees[g],
                )  # fmt: skip
                if step.ok:
                    self.on_plan = True
                    break
            if may_correct and not self.plan_steps_first and not step.ok:
                self.ran = self.corrected_step(g)
                if self.ran is not None:
                    why = f"{step.diagnosis}; executed the plan's step, corrected (8.4)"
                    local._log_failure(cycle, leg, step.phase, state, why)
        if self.ran is None:
            step = self.anew(driver, leg, step)
        if self.ran is None:
            return step
        self.g, self.steps, self.corrected = self.g + 1, self.steps + 1, self.corrected + 1
        driver.run.fails_in_row = 0
        self.ex.monitor.metrics.cycles += 1
        if self.g == len(self.guide):
            driver.queue = _queue_after(self.st.gait, leg)
        return None

    def anew(self, driver, leg: int, step):
        """Lambda_t's step where ``step`` (onto the plan's foothold) is None or failed.

        Shorter steps over a more centred body before the leg is given up (8.5's
        ambitions); a failed body move leaves the robot standing where it was measured.
        Where none is found, the plan's own step, corrected, held to the balance margin
        the plan's path samples keep (``PATH_BALANCE_MARGIN_M``) instead of the
        keyframes' (sets ``ran``).
        """
        from planner.body import stability

        local, state, tau = self.local, self.states.last, driver.run.tau
        for frac, shrink in BACKOFF if step is None or not step.ok else ():
            stride = local.stride_at(state, leg, tau) * driver.step_scale[leg] * frac
            step = local.step(state, leg, tau, stride, shrink)
            if step.ok:
                break
        if self.guided and self.ranges is not None and not step.ok:
            margin_m = stability.PATH_BALANCE_MARGIN_M
            self.ran = self.corrected_step(self.g, balance_m=margin_m)
            if self.ran is not None:
                why = f"{step.diagnosis}; executed the plan's step, corrected (8.4), "
                why += f"{margin_m * 1000:.0f} mm inside its supports"
                local._log_failure(driver.run.cycles, leg, step.phase, state, why)
        return step

    def stepped(self, driver, leg: int, step) -> None:
        """The guide's next step, or (off the guide) the leg to the queue's back."""
        self.steps += 1
        if not self.guided:
            driver.queue.push(leg)
            return
        self.g += 1
        self.followed += int(self.on_plan)
        if self.g == len(self.guide):
            driver.queue = _queue_after(self.st.gait, leg)

    def missed(self, driver, leg: int, step) -> None:
        """A failed cycle: the rest planned anew, the guide left, or the queue's swap.

        The plan's steps no longer fit, the gait queue's fail, or failures come between
        steps that bring the COM no nearer the goal (a livelock that never fails
        ``GUIDE_FAILS`` times in a row): the rest is planned anew from the measured state.
        """
        run, new = driver.run, None
        stalled = run.cycles - max(run.best_at, self.replanned_at) >= self.no_progress_cycles // 2
        if (run.fails_in_row >= GUIDE_FAILS or stalled) and len(self.replans) < REPLANS:
            new = replan_rest(
                self.states.robot, self.states.terrain, self.plan.friction, self.st,
                self.states.last, self.plan.goal[:2], run.tau,
            )  # fmt: skip
            self.replans.append(0 if new is None else len(planned_steps(new)))
            self.replanned_at = run.cycles
        if new is not None:
            self.follow(new)
            run.fails_in_row = 0
        elif self.guided and run.fails_in_row >= GUIDE_FAILS:  # the plan's steps no longer fit
            self.g = len(self.guide)
            driver.queue = _queue_after(self.st.gait, leg)  # the leg that failed goes last
        elif not self.guided:
            driver.queue.swap(leg, run.fails_in_row)
        self.ex.monitor.metrics.replans += 1

    def after(self, driver, step) -> str:
        """Execute the step's body move and swing (the planner's time law); a fall stops."""
        if step is None:  # the plan's step, corrected, was executed
            return "" if self.ran else _fell(self.ex)
        if step.moved is None:
            return ""  # the body move failed: nothing to execute
        return self.states.execute(*self.local.step_samples(step))


def _planned_settings(plan):
    """The local planner's settings the plan was made with (``stats.settings``), else defaults.

    Feedback re-plans with them: a plan made with ``--body-accel 0.2`` is walked so.
    """
    from planner.planning.local import LocalSettings
    from planner.planning.settings import SETTINGS, resolve

    known = {s.name for s in SETTINGS}
    recorded = {k: v for k, v in (plan.stats.get("settings") or {}).items() if k in known}
    recorded.pop("mu", None)  # the plan's friction is passed on its own
    recorded.pop("time_budget_s", None)  # a budget for planning a whole walk, not a step
    try:
        return resolve(options=recorded).local
    except InputError:
        return LocalSettings()


def _execute(ex, robot, sim, path: list, times: _Array) -> bool:
    """Follow planned states ``path`` at plan ``times`` from the current set-points (8.3).

    One cycle of the monitor; False when the robot fell.
    """
    from planner.body.state import contact_mask

    q = np.array([robot.q_from(p.base_position_W, p.base_quaternion_xyzw, p.joints_rad)
                  for p in path])  # fmt: skip
    contact = np.array([contact_mask(s.stratum) for s in path])
    q = blend_in(robot, q, contact, times, sim.targets())
    ex.monitor.keyframe(0)
    ex.monitor.metrics.cycles += 1
    return bool(ex.follow(times, q, contact))


# ------------------------------------------------------------------------------ 8.4
def correct_cycle(
    robot,
    plan_q: _Array,
    plan_contact: NDArray,
    plan_centres: _Array,
    meas: Measurement,
    times: _Array | None = None,
    current_joints: _Array | None = None,
) -> tuple[_Array, int]:
    """Corrected set-points of one cycle of a plan from a measurement (section 8.4).

    ``plan_q`` (n, 19), ``plan_contact`` (n, 4), ``plan_centres`` (n, 4, 3): the cycle's
    samples, foot sphere centres from FK. With ``times`` (n,) and ``current_joints``
    (12,, robot order; the set-points now), the jump from the current set-points to the
    corrected ones is spread over the cycle's four-feet phase (until the first lift-off).
    The base starts at its measured pose and reaches the plan's (shifted by the feet's
    mean offset) by the end of that four-feet phase: a plan's body attitude 16 degrees
    from the measured one (gen:12:0.6) is turned to, not commanded at once. Where feet
    then leave their legs' reach, the body is moved toward them by one offset for the
    cycle (at most ``REACH_SHIFT_M``), taken on over the same phase.
    Returns (corrected q (n, 19), IK misses: legs out of reach summed over samples).
    """
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import (
        quat_from_rotation,
        rotation_from_quat,
        rotation_from_vector,
    )

    kin = kinematics_of(robot)
    c_meas = _foot_centres(robot, meas.q)
    n = len(plan_q)
    out = plan_q.copy()
    # the measured base relative to the plan's first (shifted) one, faded out over the
    # four-feet phase: a world-frame rotation vector and a translation
    k_end = _four_feet_end(plan_contact)
    d, pos_err, rot_err = _base_error(plan_q[0], plan_contact[0], plan_centres[0], c_meas, meas)
    clock = np.arange(n, dtype=float) if times is None else np.asarray(times, float)
    span = max(float(clock[max(k_end, 0)] - clock[0]), 1e-9)
    lift = [None] * 4  # sample of lift-off and of touchdown, per leg
    for i in range(4):
        up = np.flatnonzero(~plan_contact[:, i])
        if up.size:
            ks = int(up[0])
            after = np.flatnonzero(plan_contact[ks:, i])
            kt = ks + int(after[0]) if after.size else n - 1
            lift[i] = (max(ks - 1, 0), kt)
    poses, targets, swinging = [], np.empty((n, 4, 3)), np.zeros((n, 4), bool)
    for k in range(n):
        w = 1.0 - min(float(clock[k] - clock[0]) / span, 1.0) if k_end > 0 else 0.0
        R = rotation_from_vector(w * rot_err) @ rotation_from_quat(plan_q[k, 3:7])
        poses.append((plan_q[k, :3] + d + w * pos_err, R, w, robot.joints_from_q(plan_q[k])))
        for i in range(4):
            if lift[i] is None or k <= lift[i][0]:  # measured start + the planned rolling
                targets[k, i] = plan_centres[k, i] + (c_meas[i] - plan_centres[0, i])
            elif k < lift[i][1]:
                a, b = lift[i]
                u = (k - a) / max(b - a, 1)
                targets[k, i] = plan_centres[k, i] + (1.0 - u) * (c_meas[i] - plan_centres[0, i])
            else:
                targets[k, i] = plan_centres[k, i]
            swinging[k, i] = lift[i] is not None and lift[i][0] < k < lift[i][1]

    def corrected(shift_W):
        """(q (n, 19), reach misses (n, 4, 3)) with the body shifted by ``shift_W``."""
        q, miss = plan_q.copy(), np.zeros((n, 4, 3))
        for k, (p, R, w, ref) in enumerate(poses):
            p = p + (1.0 - w) * shift_W  # the shift grows as the measured error fades
            joints, miss[k] = _corrected_legs(kin, p, R, targets[k], ref, swinging[k])
            q[k] = robot.q_from(p, quat_from_rotation(R) if w > 0.0 else plan_q[k, 3:7], joints)
        return q, miss

    # a foot the plan has at its leg's reach, measured a few millimetres off, is out of
    # reach of the plan's body: the whole cycle's body is moved toward it (one constant
    # offset, reached over the four-feet phase like the measured error's correction)
    shift = np.zeros(3)
    out, miss = corrected(shift)
    for _ in range(REACH_SHIFTS):
        if not miss.any():
            break
        total = miss.sum(axis=1)  # (n, 3): each sample's pull on the body
        trial = shift + total[int(np.argmax(np.linalg.norm(total, axis=1)))]
        if np.linalg.norm(trial) > REACH_SHIFT_M:
            break
        q_t, miss_t = corrected(trial)
        if _misses(miss_t) >= _misses(miss):
            break
        shift, out, miss = trial, q_t, miss_t
    misses = _misses(miss)
    if times is not None and current_joints is not None:
        out = blend_in(robot, out, plan_contact, times, current_joints)
    return out, misses


def _misses(miss: _Array) -> int:
    """Legs out of reach, summed over samples, of reach misses (n, 4, 3)."""
    return int(np.count_nonzero(np.linalg.norm(miss, axis=-1) > 0.0))


def _corrected_legs(kin, p: _Array, R: _Array, targets_W: _Array, ref: _Array, swinging):
    """(joints (4, 3), reach misses (4, 3) world [m]) of the legs for body pose (p, R).

    Each foot's IK on the plan sample's own knee branch: a leg the plan landed on its
    other knee beside an edge (LocalPlanner._other_knee_landing) keeps it; the leg's
    default branch put barrier75mm's FR shank 33 mm into the barrier. A miss is the
    target less the closest reachable foot centre (zero where reached); a swinging leg
    whose IK jumps to another solution than the plan's keeps the plan's joints (a
    joint-space swing over an edge flips the knee mid-air: the foot off by the body's
    correction until it lands), not a miss.
    """
    joints, miss = np.empty((4, 3)), np.zeros((4, 3))
    for i in range(4):
        target_B = R.T @ (targets_W[i] - p)
        res = kin.ik_leg(i, target_B, reference_rad=ref[i], knee=kin.knee_direction(i, ref[i]))
        if swinging[i] and float(np.max(np.abs(res.joints_rad - ref[i]))) > SWING_JUMP_RAD:
            joints[i] = ref[i]
            continue
        joints[i] = res.joints_rad
        if not res.reachable:
            miss[i] = R @ (target_B - kin.foot_B(i, res.joints_rad))
    return joints, miss


def _base_error(
    plan_q0: _Array, plan_contact0: NDArray, plan_centres0: _Array, c_meas: _Array, meas
):
    """(feet's mean offset d (3,), base position error (3,) [m], rotation vector (3,) [rad]).

    The measured base against the plan's first sample shifted by the mean offset ``d`` of
    the measured stance feet (sphere centres ``c_meas`` (4, 3), :func:`_foot_centres`) from
    the plan's (world frame), as :func:`correct_cycle` uses.
    """
    from planner.core.lie import rotation_from_quat, vector_from_rotation

    down = np.asarray(plan_contact0, bool)
    d = np.mean((c_meas - plan_centres0)[down], axis=0) if down.any() else np.zeros(3)
    rot_err = vector_from_rotation(
        rotation_from_quat(meas.q[3:7]) @ rotation_from_quat(plan_q0[3:7]).T
    )
    return d, meas.q[:3] - (plan_q0[:3] + d), rot_err


def _four_feet_end(contact: NDArray) -> int:
    """Last sample of the four-feet phase that opens a cycle (-1: it opens on three feet)."""
    up = np.flatnonzero(~np.asarray(contact, bool).all(axis=1))
    return int(up[0]) - 1 if up.size else len(contact) - 1


def _four_feet_span_s(times: _Array, contact: NDArray) -> float:
    """Duration [s] of the four-feet phase that opens a cycle (until its first lift-off)."""
    return float(times[max(_four_feet_end(contact), 0)] - times[0])


def _correction_time_s(robot, pos_err: _Array, rot_err: _Array, local=None) -> float:
    """Least time [s] to bring the body from its measured pose to the plan's (8.4).

    The base's error, and its rotation's at the hips (the lever of the farthest hip), moved
    from rest to rest under the planner's body-move time law (``body_speed_m_s``,
    ``body_accel_m_s2`` of ``local``'s settings; LittleDog's defaults without it). The plan's
    four-feet phase is timed for the plan's own move, 0.2 s for millimetres: barrier75mm's
    body, 2.8 cm off the plan after steps planned anew, was pulled back in those 0.2 s and
    the robot tipped as the next foot lifted, and fell.
    """
    from planner.body.kinematics import hip_point_B
    from planner.motion.time_law import rest_to_rest_durations_s
    from planner.planning.local import BODY_ACCEL_M_S2, BODY_SPEED_M_S

    st = getattr(local, "settings", None)
    speed = getattr(st, "body_speed_m_s", None) or BODY_SPEED_M_S
    accel = getattr(st, "body_accel_m_s2", None) or BODY_ACCEL_M_S2
    lever = max(float(np.linalg.norm(hip_point_B(leg))) for leg in robot.legs)
    err = max(float(np.linalg.norm(pos_err)), lever * float(np.linalg.norm(rot_err)))
    return float(rest_to_rest_durations_s(np.array([err]), np.array([speed]), accel)[0])


def blend_in(robot, q: _Array, contact: NDArray, times: _Array, current_joints: _Array) -> _Array:
    """Set-points ``q`` (n, 19) that start from ``current_joints`` (12,, robot order).

    The difference between the servos' set-points now and the first new sample (the
    servo error that holds the robot up, when the new samples start from a measured
    configuration; a correction's jump) fades out linearly over the four-feet phase
    that opens the cycle (until its first lift-off).
    """
    n = len(q)
    if n < 2:
        return q
    up = np.flatnonzero(~np.asarray(contact, bool).all(axis=1))
    t_end = times[up[0] - 1] if up.size and up[0] > 1 else times[-1]
    span = max(float(t_end - times[0]), 1e-9)
    jump = np.asarray(current_joints, float).reshape(4, 3) - robot.joints_from_q(q[0])
    out = q.copy()
    for k in range(n):
        w = 1.0 - min(float(times[k] - times[0]) / span, 1.0)
        if w > 0.0:
            out[k] = robot.q_from(q[k, :3], q[k, 3:7], robot.joints_from_q(q[k]) + w * jump)
    return out


def _follow_corrected(
    ex,
    meas,
    robot,
    terrain,
    s: Samples,
    centres,
    a: int,
    b: int,
    sim,
    local=None,
    refused=None,
    balance_m: float | None = None,
):
    """Execute plan samples a..b corrected from the measurement ``meas`` (8.4), or None.

    One correction, from the measurement the cycle was planned from, for the whole step.
    None, with nothing executed, when the corrected samples leave a leg's reach, bring
    the COM (Pinocchio, of the corrected joints) too near a three-foot support's edge (the
    plan's balance is kept only where every foot is where the plan had it, up to one
    common offset), or put a thigh or shank on the sharp terrain deeper than at the start
    (the plan's swing over an edge, from a body a few centimetres off, hit barrier75mm);
    else whether the robot is still standing.

    Balance asks ``balance_m`` at every three-foot sample, by default (None) the keyframes'
    ``BALANCE_MARGIN_M`` (25 mm), 5 mm more than the plan's own path samples keep: the
    step is a fallback, executed open loop from a state the plan was not made for, with
    errors the correction does not model (the feet's rolling, the servos' sag). At 20 mm
    gen:11's corrected hind-leg swing after a 6 cm step down (21-22 mm all along) tipped
    the body 34 degrees; with 25 mm the step is refused, the gait queue steps instead, and
    the walk reaches the goal (the generated physics bench: 24 of 25 feedback runs, from
    23). :func:`run_feedback` asks the path samples' 20 mm only where no step planned
    anew is found at all.

    With ``local`` (a :class:`~planner.planning.local.LocalPlanner`) the corrected samples,
    before the servo blend, must also pass the check every path planned anew passes
    (:meth:`~planner.planning.local.LocalPlanner.path_problem`: body box, leg links between
    samples, friction cones, joint torques, the final stance's sway), so that a corrected
    step is never held to less than a step planned anew (barrier75mm's plan of 1bc79ed,
    its steps corrected first: one asked FR's knee for more than the 80 % of its effort a
    path then allowed; 70 % since). A body measured off the plan is brought back over a
    four-feet hold as long as :func:`_correction_time_s` asks, where the cycle's own
    four-feet phase is shorter. Where a gate refuses, its reason is appended to the list
    ``refused``.
    """
    from planner.body import stability
    from planner.body.kinematics import kinematics_of
    from planner.body.links import leg_links
    from planner.core.lie import rotation_from_quat

    balance_m = stability.BALANCE_MARGIN_M if balance_m is None else balance_m
    times, contact = s.time[a : b + 1], s.contact[a : b + 1]
    plan_q, plan_centres = s.q[a : b + 1], centres[a : b + 1]
    c_meas = _foot_centres(robot, meas.q)
    _, pos_err, rot_err = _base_error(plan_q[0], contact[0], plan_centres[0], c_meas, meas)
    hold = _correction_time_s(robot, pos_err, rot_err, local) - _four_feet_span_s(times, contact)
    if hold > 0.0:  # the body is brought back to the plan no faster than the time law allows
        times = np.concatenate([times[:1], times + hold])
        contact, plan_q = np.concatenate([contact[:1], contact]), np.vstack([plan_q[:1], plan_q])
        plan_centres = np.concatenate([plan_centres[:1], plan_centres])
    q_body, misses = correct_cycle(robot, plan_q, contact, plan_centres, meas, times)
    if misses:
        return _refuse(refused, f"the corrected step leaves a leg's reach at {misses} samples")
    q = blend_in(robot, q_body, contact, times, sim.targets())
    kin, links = kinematics_of(robot), leg_links(robot)
    floor = None
    for qk, ck in zip(q, contact, strict=True):
        bare = links.path_margin(terrain, qk, np.flatnonzero(~ck), scale=0.0)
        floor = np.minimum(bare, 0.0) if floor is None else floor
        if np.any(bare < floor - 1e-4):
            c = int(np.argmin(bare - floor))
            return _refuse(refused, f"the corrected step puts the {links.describe(c)} deeper")
        if ck.sum() != 3:
            continue
        R, joints = rotation_from_quat(qk[3:7]), robot.joints_from_q(qk)
        feet = kin.feet_W(qk[:3], R, joints)[ck]
        com = qk[:3] + R @ kin.com_B(joints)
        if (tip := stability.support_margin_m(feet, com)) < balance_m:
            why = f"the corrected step's COM {tip * 1000:.1f} mm inside its support"
            return _refuse(refused, f"{why} (< {balance_m * 1000:.0f} mm)")
    if local is not None:
        centres_W = np.array([_foot_centres(robot, qk) for qk in q_body])
        path = states_of_samples(robot, terrain, q_body, contact, times, centres_W)
        if why := local.path_problem(path):
            return _refuse(refused, f"the corrected step: {why}")
    ex.monitor.keyframe(0)
    return ex.follow(times, q, contact)


def _refuse(refused: list | None, why: str) -> None:
    """None (a corrected step not executed), its reason appended to ``refused`` if given."""
    if refused is not None:
        refused.append(why)
    return None


def run_corrected(
    plan: Plan,
    settings: SimSettings | None = None,
    source: StateSource | None = None,
    **noise,
) -> SimResult:
    """Execute the precomputed plan, correcting it from the measured state (8.4).

    Corrections are made at every cycle start (touchdown) and again at every lift-off, so
    that the swing foot is aimed from where the body really is. ``noise`` as in
    :func:`run_feedback`.
    """
    wall0 = _time.perf_counter()
    sim, ex = new_run(plan, settings, "precompute-then-correct")
    t0 = sim.time
    src = _source(sim, source, **noise)
    robot = plan.load_robot()
    s = plan.samples
    centres = plan.foot_centres_W()
    cycles = set(cycle_starts(s.contact))
    allc = s.contact.all(axis=1)
    lifts = {k for k in range(1, len(s) - 1) if allc[k] and not allc[k + 1]}
    starts = sorted(cycles | lifts | {len(s) - 1})
    m = ex.monitor.metrics
    try:
        for a, b in zip(starts[:-1], starts[1:], strict=True):
            meas = src.measure()
            q, misses = correct_cycle(
                robot,
                s.q[a : b + 1],
                s.contact[a : b + 1],
                centres[a : b + 1],
                meas,
                s.time[a : b + 1],
                sim.targets(),
            )
            m.ik_misses += misses
            if a in cycles:
                ex.monitor.keyframe(0)
                m.cycles += 1
            if not ex.follow(s.time[a : b + 1], q, s.contact[a : b + 1]):
                break
    except KeyboardInterrupt:
        ex.interrupt()
    return finish_run(plan, ex, wall0, t0)


# ------------------------------------------------------------------------------ perturbing
def shift_body(plan: Plan, offset_W: ArrayLike, mask: ArrayLike | None = None) -> Plan:
    """A copy of ``plan`` with the body moved by ``offset_W`` [m] against its feet.

    In the samples selected by ``mask`` (all by default) the base position moves by the
    offset and the joints are re-solved (leg IK) so that every foot stays where the plan
    put it: the centre of mass moves by about the offset relative to the support. Used to
    make a plan that must fail on a body with mass.
    """
    from planner.body.kinematics import kinematics_of
    from planner.core.lie import rotation_from_quat

    robot = plan.load_robot()
    kin = kinematics_of(robot)
    off = np.asarray(offset_W, float).reshape(3)
    sel = np.ones(len(plan.samples), bool) if mask is None else np.asarray(mask, bool)
    centres = plan.foot_centres_W()
    q = plan.samples.q.copy()
    for k in np.flatnonzero(sel):
        p = q[k, :3] + off
        R = rotation_from_quat(q[k, 3:7])
        ref = robot.joints_from_q(q[k])
        joints = np.array(
            [
                kin.ik_leg(i, R.T @ (centres[k, i] - p), reference_rad=ref[i]).joints_rad
                for i in range(4)
            ]
        )
        q[k] = robot.q_from(p, q[k, 3:7], joints)
    out = Plan.from_dict(plan.to_dict(), source=f"{plan.source} (body shifted {off.tolist()})")
    out.samples = Samples(plan.samples.time.copy(), q, plan.samples.contact.copy())
    out._robot_cache, out._terrain_cache = plan._robot_cache, plan._terrain_cache
    return out


def simulate_plan(
    plan: Plan | str | Path,
    mode: str = "open",
    settings: SimSettings | None = None,
    **kwargs: Any,
) -> SimResult:
    """Simulate a plan: ``mode`` "open" (open loop), "correct" (8.4) or "feedback" (8.3).

    ``kwargs`` go to :func:`run_corrected` or
    :func:`run_feedback` (noise, latency, ...).
    """
    if not isinstance(plan, Plan):
        plan = Plan.load(plan)
    if mode == "open":
        return run_open_loop(plan, settings)
    if mode == "correct":
        return run_corrected(plan, settings, **kwargs)
    if mode == "feedback":
        return run_feedback(plan, settings, **kwargs)
    raise InputError(f"simulate: unknown mode {mode!r}; use open, correct or feedback")


# ------------------------------------------------------------------------------ command line
def cmd_simulate(args) -> int:
    """Run ``stratawalk simulate``; exit 0 when the run is OK, 1 otherwise.

    Ctrl-C or SIGTERM stop the run: the motion so far is judged and written (``--out``),
    exit 130 / 143 (:mod:`planner.core.interrupts`).
    """
    from planner.core.interrupts import Interrupts
    from planner.core.outputs import check_file

    if args.out:
        check_file(args.out, "--out")
    plan = Plan.load(args.plan, robot=args.robot)
    settings = SimSettings(
        time_scale=args.time_scale, timestep_s=args.timestep, feedforward=not args.no_feedforward
    )
    settings.control_dt_s = max(settings.control_dt_s, settings.timestep_s)
    mode = "feedback" if args.feedback else "correct" if args.correct else "open"
    if args.plan_steps_first and mode != "feedback":
        raise InputError("--plan-steps-first: a feedback option; add --feedback")
    kwargs = {}
    if mode != "open":
        kwargs = {
            "position_noise_m": args.noise_mm / 1000.0,
            "angle_noise_rad": math.radians(args.noise_deg),
            "latency_s": args.latency,
            "seed": args.seed,
        }
    if args.plan_steps_first:
        kwargs["plan_steps_first"] = True
    if args.trajectory:
        from planner.planfile.export import load_trajectory, plan_from_trajectory

        if mode != "open":
            raise InputError("--trajectory: executes open loop; drop --feedback/--correct")
        traj = load_trajectory(args.trajectory)
    bar = None if args.quiet else _progress_bar(plan)
    with Interrupts() as stop, reporting_progress(bar):
        if args.trajectory:
            res = run_open_loop(plan_from_trajectory(plan, traj), settings, traj.torque_ff)
        else:
            res = simulate_plan(plan, mode, settings, **kwargs)
        if bar is not None:
            print(file=sys.stderr)
        print(res.metrics.summary())
        if args.out:
            with stop.shielded():
                path = res.executed.save(args.out)
            print(f"wrote {path}: {len(res.executed.samples)} executed samples")
    if stop.exit_code is not None:
        return stop.exit_code
    return 0 if res.metrics.ok else 1


def _progress_bar(plan: Plan):
    """A ``progress(sim)`` that prints a bar of the simulated walk.

    The bar is how far the COM has come towards the plan's goal (the furthest so far:
    monotone), with the simulated time; at most twice a second.
    """
    start, goal = plan.start[:2], plan.goal[:2]
    total = max(float(np.linalg.norm(goal - start)), 1e-9)
    state = {"done": 0.0, "shown": 0.0}

    def progress(sim) -> None:
        now = _time.monotonic()
        if now - state["shown"] < 0.5:
            return
        state["shown"] = now
        dist = float(np.linalg.norm(sim.com_W()[:2] - goal))
        state["done"] = max(state["done"], min(1.0, 1.0 - dist / total))
        bar = "#" * int(30 * state["done"])
        print(f"\r[{bar:<30}] {100 * state['done']:5.1f}%  simulated {sim.time:6.1f} s",
              end="", file=sys.stderr, flush=True)  # fmt: skip

    return progress
