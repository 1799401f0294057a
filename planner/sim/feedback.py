"""Feedback from the measured state (paper section 8.3, with 8.4's corrected steps).

:func:`run_feedback`: every cycle (one gait step) the soft-persuasion planner of 8.2
starts from the *measured* configuration (:mod:`planner.sim.measure`): measured base
pose and joints, the stance feet where the robot's feet actually are (projected onto the
terrain), and plans the next step from there (Theta2 body move, Theta3 foothold), which
the simulator then executes. The cycles, the gait queue, its failure handling and the
stop rules are the planners' driver's (:class:`planner.planning.driver.GaitDriver`), its
states measured (:class:`MeasuredStates`), its cycle following the precomputed plan
(:class:`PlanFollowing`: the plan's steps, planned anew from the measured state, else
corrected as in 8.4, else the rest of the walk re-planned, :func:`replan_rest`). Slip,
rolling of the feet and servo compliance do not accumulate: each step starts from the
truth.
"""

from __future__ import annotations

import time as _time

import numpy as np
from numpy.typing import NDArray

from planner.core.errors import InputError
from planner.planfile.plan import Plan
from planner.planning.driver import QueueCycle
from planner.sim.correction import _follow_corrected, blend_in
from planner.sim.measure import Measurement, StateSource, _source, measured_state
from planner.sim.simulate import SimResult, SimSettings, cycle_starts, finish_run, new_run

__all__ = [
    "MeasuredStates",
    "PlanFollowing",
    "planned_body_poses",
    "planned_knees",
    "planned_steps",
    "plan_step_cycles",
    "replan_rest",
    "run_feedback",
]

_Array = NDArray[np.float64]

# (stride fraction, Lambda_c shrink) tried in turn for one step from a measured state
BACKOFF = ((1.0, None), (0.5, 0.5), (0.25, 0.7))
GUIDE_FAILS = 2  # failed cycles in a row after which feedback stops following the plan's steps
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

    When the precomputed plan's steps no longer fit the measured state (e.g. the
    robot 1 cm off the plan's pose beside a barrier, a knee near its limit), the soft
    planner (8.2, with its look-ahead and retrace) plans from there to the goal within
    ``REPLAN_BUDGET_S``; where it stalls, the recursive planner (8.5, which traces back
    and tries shorter strides) gets the same budget. Its steps become the guide. None
    when neither reaches the goal: a re-plan that stops short would be followed into its
    dead end, where the gait queue's greedy steps from the measured state may still reach
    the goal.
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
