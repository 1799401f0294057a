"""What every local planner of section 8 shares (8.1, 8.2, 8.5).

A *step* (section 8.5's word) is the cycle of figure 6 for one leg i_f: move the body on
the current leaf of S0 onto the three other legs (Theta1 or Theta2), lift i_f, swing it
clear of the terrain and place it with Theta3 (S0 -> S_if -> S0). :class:`LocalPlanner`
builds and caches the Theta problems, makes steps (:meth:`LocalPlanner.step`) and records
them in a :class:`Walk` (keyframes and dense samples). The planners differ only in how
they choose the next step and what they do when one fails (:meth:`LocalPlanner._run`).

Planning stops when the centre of mass is within ``goal_tol_m`` of the goal, when the
step, cycle or time budget runs out, on Ctrl-C, or when the planner is stuck; whatever was
planned is kept and returned.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from planner.body.contact import sphere_penetration_m
from planner.body.kinematics import hip_point_B, kinematics_of
from planner.body.links import leg_links
from planner.body.robot import LEG_NAMES
from planner.body.rolling import end_keyframe
from planner.body.stability import (
    BALANCE_MARGIN_M,
    PATH_BALANCE_MARGIN_M,
    nearest_inside_point_W,
    polygon_margin_m,
    support_margin_m,
    triangle_inradius_m,
)
from planner.body.state import State
from planner.body.stiffness import sway_stiffness_of
from planner.body.torques import COMMANDED_TORQUE_FRACTION, TorqueCheck
from planner.core import interrupts
from planner.core.lie import rotation_from_quat
from planner.core.units import GRAVITY_M_S2
from planner.motion.footholds import best_and_shortest, foothold_candidates
from planner.motion.gait_queue import CRAWL
from planner.motion.heuristics import (
    EDGE_MARGIN_M,
    TARGET_REACH_FRACTION,
    body_clearance_height_m,
    foothold_hazard,
    frame_from_directions,
    lambda_c,
    lambda_t,
    nominal_height_m,
    reach_height_cap_m,
    reference_directions,
    safe_foothold,
    support_body_target_W,
    support_plane_W,
    two_beat_xy_W,
)
from planner.motion.interpolate import (
    BETWEEN_SAMPLES_RAD,
    BETWEEN_STEP_RAD,
    between_q,
    default_clearance_m,
    interpolate_leaf,
    interpolate_swing,
)
from planner.motion.leg_swing import joint_space_swing
from planner.motion.trajectory import Trajectory
from planner.problems import Theta1, Theta2, Theta3, Theta4
from planner.problems.base import ConstraintCheck
from planner.problems.options import LocalSettings

# the time law (planner.motion.time_law), chosen from MuJoCo runs at time scale 1 (issue 16):
BODY_SPEED_M_S = 0.25  # LittleDog's body moves, peak [m/s] (x sqrt(s) for another robot)
# ... their acceleration bound [m/s^2], lower where the stance cannot carry it: the 10 cm
# climb (tests/test_climb.py) slid and fell open loop at 1.0 and 1.5 (its body overshot a
# fast move by 2 cm before a swing), and was executed as planned at 0.5
BODY_ACCEL_M_S2 = 0.5
SWING_TIME_S = 0.25  # LittleDog's least swing [s] (x sqrt(s))
BODY_CLEARANCE_M = 0.005  # least height of the body's bottom above the sharp terrain [m]
FOOT_CUT_TOL_M = 1e-4  # a stance foot sphere may overlap the sharp terrain this much (check's)
KNEE_CHOICE_CLEARANCE_M = 0.015  # a landing whose links are nearer an edge than this ...
KNEE_CHOICE_GAIN_M = 0.01  # ... takes the other knee branch if it is this much clearer
KNEE_CHOICE_EDGE_M = 0.06  # ... next to an edge this much higher than the foothold
KNEE_CHOICE_LOOKAHEAD = 0.5  # fraction of a stride the body is moved ahead to judge it
KNEE_CHOICE_FOOT_ZONE_M = 0.03  # (link points this near the foot centre do not count)
# a landing next to a tall edge must let the body pass over the foot (foothold_passage):
PASSAGE_STRIDES = (0.5, 1.0)  # the body this many strides further along ...
PASSAGE_RAISES_M = (0.0, 0.01, 0.02)  # ... at its nominal height or this much higher ...
PASSAGE_CLEARANCE_M = 0.005  # ... keeps the leg's links (away from the foot) this clear
OTHER_FOOTHOLDS = 8  # footholds tried when the body cannot get ready for Lambda_t's
FAILED_MOVES_KEPT = 4096  # failed body moves remembered in a run (LocalPlanner._body_move_once)
CANDIDATE_POOL = 40  # candidates scored before the best and the shortest are picked
CANDIDATE_LATERAL_M = 0.05  # other footholds within this of the failed one sideways [m]
DEAD_END_LATERAL_M = 0.08  # ... of the nominal placement, when the foothold is a dead end
# every body target sinks where a leg would be stretched beyond this share of its reach
# (a crawl stance on flat ground reaches 0.94 before a hind leg swings, untouched): with
# three feet up a 10 cm step the footholds' plane put the body 4 cm too high for the fourth
ALWAYS_REACH_FRACTION = 0.95
TARGET_RADIUS_M = 0.01  # a placed foot lands within this of its (edge-free) target [m]
WIDE_TARGET_RADIUS_M = 0.04  # ... or this, when the leg's links forbid the near footholds
# joint torque / URDF effort the servos may need to hold a sample (planner.body.torques)
TORQUE_FRACTION = COMMANDED_TORQUE_FRACTION
# feedback (8.3) starts paths at a measured state that may already lack a margin by a
# fraction of a millimetre; a path from it may not lose more than this
START_SLACK_M = 1e-4
PROGRESS_M = 0.01  # the COM coming this much nearer the goal counts as progress
ARRIVAL_M = 0.01  # a walk ending within goal_tol_m but farther than this tries the arrival
# com_target "two_beat": the COM stays put, or moves to the deepest point of two supports,
# where it is this far inside (Theta2's own margin, BALANCE_MARGIN_M, and 5 mm to spare for
# the pose Theta2 finds near the target)
TWO_BEAT_MARGIN_M = BALANCE_MARGIN_M + 0.005
# stride_at: the ground under a long stride counts as level within these
LEVEL_TOL_M = 0.005  # heights off the feet's plane [m]
LEVEL_SLOPE = 0.09  # the feet's plane's gradient (5 degrees)
LEVEL_WIDTH_M = 0.03  # the swing track's half width [m]
LEVEL_GRID_M = 0.01  # spacing of the heights sampled [m]
MAX_START_TORQUE_FRACTION = 0.9  # ... but never past this (nor below zero clearance):
# without the bounds, each path could lose a little more than the last (a ratchet)


@dataclass
class LocalPlan:
    """What a local planner produced: key configurations, dense samples, outcome."""

    keyframes: list[State]
    samples: list[State]
    times: list[float]
    reached_goal: bool
    distance_to_goal_m: float
    message: str
    stats: dict


@dataclass
class Step:
    """The outcome of one step attempt for ``leg`` from ``start``.

    ``moved``: the state after the body move (None if it failed); ``end``: after the
    placement, back on S0 (None if the step failed). ``phase`` names the failed part
    ("body_move" or "foot_placement"), ``diagnosis`` says why.
    """

    leg: int
    ok: bool
    start: State
    moved: State | None
    end: State | None
    body_path: list[State]
    swing_path: list[State]
    phase: str = ""
    diagnosis: str = ""
    # the swing overlapping the body move (planner.planning.overlap), set by step_samples
    overlap: object = field(default=None, repr=False)
    timed: bool = field(default=False, repr=False)


@dataclass
class _Run:
    """The fixed inputs and counters of one planning run."""

    goal: np.ndarray
    tau: Trajectory
    t_begin: float
    progress: object = None
    cycles: int = 0
    last_failure: str = ""
    best_dist_m: float = float("inf")  # nearest the COM came to the goal ...
    best_at: int = 0  # ... and in which cycle
    arrival_tried: int = -1  # keyframe count at the last arrival attempt


class Walk:
    """Keyframes and timed dense samples of a walk being planned; can be rewound.

    The steps are kept as recorded; their samples and times, which need each step's swing
    overlap (:meth:`LocalPlanner.step_samples`), are put together when first asked for,
    the overlaps searched meanwhile by ``worker`` where there is one
    (:class:`planner.planning.prefetch.OverlapWorker`).
    """

    def __init__(self, planner: LocalPlanner, state: State, worker=None):
        self.planner = planner
        self.start = state
        self.parts: list[Step] = []  # the recorded steps (placements, failed ones, arrivals)
        self.steps = 0
        self.worker = worker
        self._timed: tuple | None = None  # (keyframes, samples, times) of ``parts``

    @property
    def state(self) -> State:
        """The current configuration (the last keyframe)."""
        if not self.parts:
            return self.start
        last = self.parts[-1]
        return last.end if last.ok else last.moved

    @property
    def n_keyframes(self) -> int:
        """How many keyframes the walk has (without timing it)."""
        return 1 + sum(3 if s.ok else 1 for s in self.parts)

    def add(self, step: Step) -> None:
        """Record a step: its body move (also of a failed placement) and its swing."""
        if step.moved is None:
            return
        self.parts.append(step)
        self.steps += int(step.ok)
        self._timed = None
        if self.worker is not None:
            self.worker.submit(step)

    def add_body_move(self, end: State, path: list[State]) -> None:
        """Record a body move on the current feet (no swing), e.g. :meth:`LocalPlanner.arrival`."""
        self.add(Step(-1, False, self.state, end, None, path, [], "arrival"))

    @property
    def keyframes(self) -> list[State]:
        """Start; per step its body move's end (a placement: its mid-swing, its landing)."""
        return self._time()[0]

    @property
    def samples(self) -> list[State]:
        """The walk's dense samples (the executor's)."""
        return self._time()[1]

    @property
    def times(self) -> list[float]:
        """The samples' times [s] from the walk's start."""
        return self._time()[2]

    def _time(self) -> tuple:
        """(keyframes, samples, times) of the recorded steps, in the executor's timing."""
        if self._timed is not None:
            return self._timed
        p, w = self.planner, self.worker
        if w is not None:
            w.finish(self.parts)
        keyframes, samples, times = [self.start], [self.start], [0.0]
        for step in self.parts:
            if w is not None:
                w.wait_for(step)
            states, t = p.step_samples(step)
            t = times[-1] + t
            n_body = max(len(step.body_path) - 1, 0)
            if step.overlap is not None:  # the leg lifts at this body sample (local.overlap)
                n_body = step.overlap.lift
            p._append(samples, times, states[: 1 + n_body], t[1 : 1 + n_body])
            keyframes.append(step.moved)
            if step.ok:
                p._append(samples, times, states[n_body:], t[1 + n_body :])
                swing = step.swing_path if step.overlap is None else states[n_body:]
                keyframes += [p._swing_keyframe(swing, step.leg, p.check), step.end]
        self._timed = (keyframes, samples, times)
        return self._timed

    def mark(self) -> tuple[int, int]:
        """A bookmark for :meth:`rewind`."""
        return len(self.parts), self.steps

    def rewind(self, mark: tuple[int, int]) -> None:
        """Forget everything recorded after ``mark`` (backtracking, section 8.5)."""
        k, n = mark
        if self.worker is not None:
            self.worker.forget(self.parts[k:])
        del self.parts[k:]
        self.steps = n
        self._timed = None

    def copy(self) -> tuple:
        """The walk so far, for :meth:`restore` after a rewind (states are not copied)."""
        return list(self.parts), self.steps

    def restore(self, kept: tuple) -> None:
        """Back to a walk kept by :meth:`copy`."""
        parts, self.steps = kept
        self.parts = list(parts)
        self._timed = None


class NearestWalk:
    """The walk that came nearest the goal before a planner traced back across it.

    Tracing back (8.5; soft's retraces) forgets steps; a planner that then stops short of
    where it had been returns this walk instead (nothing computed is lost).
    """

    def __init__(self) -> None:
        self.kept: tuple | None = None
        self.dist_m = np.inf

    def offer(self, walk: Walk, dist_m: float) -> None:
        """Keep ``walk`` (about to be rewound) if it is the nearest so far."""
        if dist_m < self.dist_m:
            self.kept, self.dist_m = walk.copy(), dist_m

    def settle(self, walk: Walk, dist_m: float, message: str) -> str:
        """Restore the kept walk where it ends ``PROGRESS_M`` nearer than ``walk``."""
        if self.kept is None or self.dist_m >= dist_m - PROGRESS_M:
            return message
        walk.restore(self.kept)
        return (
            f"{message}; the plan is the walk that came nearest ({100 * self.dist_m:.0f} cm "
            f"from the goal) before it was traced back"
        )


class LocalPlanner:
    """The shared part of the local planners, for one robot on one terrain.

    Theta problems are built once per support pattern or swing leg and cached; initial
    placement is Theta4 (7.5); :meth:`step` makes one step; subclasses implement
    :meth:`_run`, the loop that chooses steps.
    """

    name = "local"
    # :meth:`step` prefers footholds after which the gait's next leg still finds a body
    # move (:meth:`next_leg_can_move`): the recursive planner's (8.5) look-ahead. Off for
    # the greedy planners: on barrier75mm it let soft take footholds that stalled later
    foothold_lookahead = False
    # :meth:`step` refuses landings next to a tall edge that stop the body passing over
    # them (:meth:`blocks_passage`)
    foothold_passage = False

    def __init__(self, robot, terrain, mu: float | None = None, settings=None):
        self.robot = robot
        self.terrain = terrain
        self.mu = float(terrain.spec.get("friction", 0.7) if mu is None else mu)
        self.settings = _timed(settings or LocalSettings(), robot)
        self.kin = kinematics_of(robot)
        self._sink = False  # body targets lowered where a leg is stretched (step's back-off)
        self._hips_B = np.array([hip_point_B(lg) for lg in robot.legs])
        self._theta2: dict[tuple[tuple[int, ...], bool], Theta2] = {}
        self._theta3: dict[int, Theta3] = {}
        self._via_theta1: dict[tuple[int, ...], Theta1] = {}
        self._failed_moves: dict[tuple, object] = {}  # body moves that failed (this run)
        self.stats = {
            "theta1": [0, 0],
            "theta2": [0, 0],
            "theta2_lookahead": [0, 0],
            "theta3": [0, 0],
            "theta4": [0, 0],
            "swing_ik": [0, 0],
            "swing_joint_space": [0, 0],
        }
        self.failures: list[dict] = []  # every failed step attempt, for the plan's stats
        self.extra_stats: dict = {}
        self.check = ConstraintCheck(robot, terrain, self.settings.theta)
        self._bottom_B = robot.body_bottom_points_B(spacing_m=0.005, rows=5)  # path checks
        self.torques = TorqueCheck(robot)

    # ---- problems, built once per support pattern / leg --------------------------------
    def theta2(self, support, landing: bool = False) -> Theta2:
        """Theta2 for a support pattern, landing-ready or not (built on first use)."""
        key = (tuple(sorted(support)), bool(landing) and len(support) == 3)
        if key not in self._theta2:
            self._theta2[key] = Theta2(
                self.robot,
                self.terrain,
                support=key[0],
                options=self.settings.theta,
                mu=self.mu,
                landing=key[1],
            )
        return self._theta2[key]

    def theta3(self, leg: int) -> Theta3:
        """Theta3 for a swing leg (built on first use)."""
        if leg not in self._theta3:
            self._theta3[leg] = Theta3(
                self.robot, self.terrain, leg, options=self.settings.theta, mu=self.mu
            )
        return self._theta3[leg]

    def _count(self, key: str, ok: bool) -> None:
        counts = self.stats.setdefault(key, [0, 0])  # theta2_held: only where two-beat
        counts[0] += 1
        counts[1] += int(ok)

    def com_height_m(self) -> float:
        """Nominal height of the whole-body COM above the terrain [m]."""
        com_B = self.kin.com_B(self.robot.theta_nor, self.settings.theta.whole_body_com)
        return nominal_height_m(self.robot) + float(com_B[2])

    # ---- initial placement (section 7.5) -----------------------------------------------
    def initial_state(self, start_xy, tau: Trajectory) -> State:
        """Theta4 at the start: body origin at the nominal height above the terrain."""
        x, y = float(start_xy[0]), float(start_xy[1])
        z = float(self.terrain.height(np.array(x), np.array(y))) + nominal_height_m(self.robot)
        p = np.array([x, y, z])
        u_f, u_n = reference_directions(tau, self.terrain, p, lam=tau.lambda_a)
        sol = Theta4(self.robot, self.terrain, self.settings.theta, self.mu).solve(p, u_f, u_n)
        self._count("theta4", sol.feasible)
        if not sol.feasible:
            from planner.core.errors import NoSolutionFound

            raise NoSolutionFound(
                f"initial placement at ({x:.3f}, {y:.3f}) failed: {sol.diagnosis}", sol
            )
        return sol.state

    # ---- one cycle ---------------------------------------------------------------------
    def foothold_target(
        self, state: State, leg: int, tau: Trajectory, step_m: float, shrink: float | None = None
    ):
        """Where ``leg`` will go: Lambda_t (eq. 13) moved off edges; returns (point, hazard).

        Lambda_t is taken with the body at r_c* (where the body move will bring it), so
        the foothold matches the stance the leg swings from; :func:`safe_foothold` then
        moves it to the nearest point of the sharp terrain without an edge under the foot
        (beyond the paper). ``hazard`` is "" or why no safe point was found nearby.
        """
        target = self.stride_target(state, leg, tau, step_m, shrink)
        u_f, _ = reference_directions(tau, self.terrain, target)
        return safe_foothold(
            self.terrain,
            target,
            u_f,
            self.robot.foot_radius_m,
            self.mu,
            max_shift_m=max(step_m, 0.5 * float(np.min(self.robot.reach_m))),
            not_behind_W=state.feet_W[leg],
        )

    def stride_target(
        self, state: State, leg: int, tau: Trajectory, step_m: float, shrink: float | None = None
    ) -> np.ndarray:
        """Lambda_t (eq. 13) with the body at r_c*: the leg's nominal placement, edges ignored."""
        rc = self.body_target(state, leg, shrink, tau=tau)
        ahead = state.copy()
        ahead.base_position_W = np.array(rc, float)
        return lambda_t(self.robot, self.terrain, ahead, leg, tau, step_m=step_m)

    def other_footholds(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        tried_W,
        shrink: float | None = None,
        centre_W=None,
        max_lateral_m: float = CANDIDATE_LATERAL_M,
        keep=None,
    ) -> list[np.ndarray]:
        """Footholds to try when the body cannot get ready for ``tried_W`` (issue 15 item 1).

        :func:`planner.motion.footholds.foothold_candidates` within ``max_lateral_m`` of
        ``centre_W`` (default ``tried_W``) at the body pose the move aims for (COM at r_c*),
        ``tried_W`` itself and those failing ``keep(point)`` left out, best-scored and
        shortest alternating (:func:`planner.motion.footholds.best_and_shortest`).
        """
        rc = self.body_target(state, leg, shrink, tau=tau)
        u_f, R, body_W = self._body_pose_at(state, leg, tau, rc)
        tried = np.asarray(tried_W, float)
        centre = tried if centre_W is None else np.asarray(centre_W, float).reshape(3)
        found = [
            c
            for c in foothold_candidates(
                self.robot, self.terrain, leg, centre, u_f, body_W, R, self.mu,
                not_behind_W=state.feet_W[leg], max_lateral_m=max_lateral_m,
                limit=CANDIDATE_POOL, accept=keep,
            )
            if np.linalg.norm(c[:2] - tried[:2]) > TARGET_RADIUS_M
        ]  # fmt: skip
        return best_and_shortest(found, state.feet_W[leg], u_f, OTHER_FOOTHOLDS)

    def body_target(
        self,
        state: State,
        leg: int,
        shrink: float | None = None,
        swing_target_W=None,
        tau: Trajectory | None = None,
    ) -> np.ndarray:
        """r_c* = Lambda_c(Psi, i_f) (eq. 12) at the nominal COM height, with ``shrink``.

        With ``follow_support`` the height follows the four footholds
        (:func:`support_body_target_W`), ``leg``'s halfway to its next one
        ``swing_target_W`` when given (the landing-ready body move ends with the leg still
        on its foothold, and from there it must reach the next one), the body facing
        along ``tau`` (not its current heading: a yaw would feed back into the target).
        """
        k = self.settings.shrink if shrink is None else shrink
        feet = self._plane_feet(state, leg, swing_target_W)
        heading = None
        if tau is not None:
            heading = tau.tangent(tau.closest_lambda(state.base_position_W))
        centre = None
        if self.settings.com_target == "two_beat" and self.level_under(state):
            centre = two_beat_xy_W(
                state, leg, self._next_leg(leg), swing_target_W, self.check.com_W(state),
                TWO_BEAT_MARGIN_M,
            )  # fmt: skip
        rc = lambda_c(
            self.robot, self.terrain, state, leg, self.com_height_m(), k, feet, heading, centre
        )
        if feet is None or tau is None:
            return rc
        return self.sunk_target(state, leg, rc, tau, swing_target_W, heading)

    def sunk_target(self, state: State, leg: int, rc, tau: Trajectory, swing_target_W, heading):
        """``rc`` lowered where a leg would be stretched, not below the body box's clearance.

        Always beyond ALWAYS_REACH_FRACTION of a leg's reach, and to TARGET_REACH_FRACTION
        when backing off from a failed step (:meth:`step`).
        """
        rc = np.array(rc, float)
        fraction = TARGET_REACH_FRACTION if self._sink else ALWAYS_REACH_FRACTION
        sink = self._reach_sink_m(state, leg, rc, tau, swing_target_W, fraction)
        if sink < 0.0:
            floor = body_clearance_height_m(self.robot, self.terrain, rc, heading)
            rc[2] = max(rc[2] + sink, min(rc[2], floor))
        return rc

    def _reach_sink_m(
        self, state: State, leg: int, rc, tau: Trajectory, swing_target_W, fraction: float
    ):
        """The body target's drop [m] that keeps every leg within ``fraction`` of reach (<= 0).

        :func:`planner.motion.heuristics.reach_height_cap_m` at the pose the move aims for: the
        three stance legs on their feet, ``leg`` on its next foothold when given.
        """
        _, R, body_W = self._body_pose_at(state, leg, tau, rc, swing_target_W)
        hips_W = self._hips_B @ R.T + body_W
        feet = np.array(state.feet_W, float)
        legs = [i for i in range(4) if i != leg]
        if swing_target_W is not None:
            feet[leg] = np.asarray(swing_target_W, float).reshape(3)
            legs.append(leg)
        centres = feet + self.robot.foot_radius_m * np.asarray(
            self.terrain.normal(feet), float
        ).reshape(4, 3)
        return reach_height_cap_m(self.robot, hips_W, centres, legs, fraction)

    def _body_pose_at(self, state: State, leg: int, tau: Trajectory, rc, swing_target_W=None):
        """(u_f, body rotation, body origin) [world] of the pose with its COM at ``rc``.

        The directions of :meth:`body_directions`, the COM offset of ``state``'s joints.
        """
        u_f, u_n = self.body_directions(tau, state, rc, leg, swing_target_W)
        R = frame_from_directions(u_f, u_n)
        body_W = rc - R @ self.kin.com_B(state.joints_rad, self.settings.theta.whole_body_com)
        return u_f, R, body_W

    def _plane_feet(self, state: State, leg: int, swing_target_W=None):
        """The footholds the body follows, or None (the paper's u_n and height)."""
        if not self.settings.follow_support:
            return None
        feet = np.array(state.feet_W, float)
        if swing_target_W is not None:  # the leg still stands at its foothold: halfway
            feet[leg] = 0.5 * (feet[leg] + np.asarray(swing_target_W, float))
        return feet

    def body_directions(self, tau: Trajectory, state: State, rc, leg: int, swing_target_W=None):
        """(u_f, u_n) of sigma1, sigma2 for the body move at r_c* before ``leg`` swings.

        u_f along tau; u_n the terrain's smoothed normal (section 7.2) or, with
        ``follow_support``, pitched with the footholds (:func:`support_body_target_W`).
        """
        u_f, u_n = reference_directions(tau, self.terrain, rc)
        feet = self._plane_feet(state, leg, swing_target_W)
        if feet is not None:
            _, u_n = support_body_target_W(
                self.robot, self.terrain, feet, rc, self.com_height_m(), u_f, u_n
            )
        return u_f, u_n

    def body_move(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        swing_target_W=None,
        shrink: float | None = None,
        hint: State | None = None,
    ):
        """Theta2 onto the three legs other than ``leg``; returns (solution, samples).

        With ``swing_target_W`` the body also keeps ``leg``'s hip within reach of its next
        foothold (Theta2's swing-ready constraint). ``hint``: Theta2's last starting pose
        (:meth:`planner.problems.theta2.Theta2.solve`). (Aiming at the hint's own pose when
        the optimum's path fails was tried: barrier9cm's feedback run then stalled.)
        """
        support = tuple(i for i in range(4) if i != leg)
        rc = self.body_target(state, leg, shrink, swing_target_W, tau)
        u_f, u_n = self.body_directions(tau, state, rc, leg, swing_target_W)
        landing = swing_target_W is not None
        if self._holds_here(state, leg):
            held = self._held(state, support, rc, u_f, u_n, swing_target_W)
            if held is not None:
                return held
        sol = self.theta2(support, landing).solve(state, rc, u_f, u_n, swing_target_W, hint)
        self._count("theta2", sol.feasible)
        if not sol.feasible:
            return sol, []
        sol.state.support = support

        def again(rolled: State):
            return self.theta2(support, landing).solve(rolled, rc, u_f, u_n, swing_target_W)

        sol, path, why = self.body_path(state, sol, again, u_f, u_n)
        if why:
            sol.feasible = False
            sol.diagnosis = f"body move onto three legs: {why}"
            return sol, []
        return self._ended(sol, path, support), path

    def _holds_here(self, state: State, leg: int) -> bool:
        """Whether the two-beat crawl keeps the body still before ``leg`` swings.

        With ``com_target`` "two_beat" on level ground, where the COM stands
        ``TWO_BEAT_MARGIN_M`` inside the triangle of the other three feet already (the
        second swing of a pair).
        """
        if self.settings.com_target != "two_beat" or not self.level_under(state):
            return False
        sup = [i for i in range(4) if i != leg]
        com = self.check.com_W(state)
        return support_margin_m(state.feet_W[sup], com) >= TWO_BEAT_MARGIN_M

    def _held(self, state: State, support, rc, u_f, u_n, swing_target_W):
        """(solution, samples) of a body move that stays where it is, or None.

        :meth:`planner.problems.theta2.Theta2.hold`: the start passes Theta2's checks on
        three legs; the path is the start twice (a move of no length, no time).
        """
        held = self.theta2(support, swing_target_W is not None).hold(
            state, rc, u_f, u_n, swing_target_W
        )
        self._count("theta2_held", held.feasible)
        if not held.feasible:
            return None
        held.state.support = support
        path = [state, held.state]
        if self.path_problem(path):
            return None
        return self._ended(held, path, support), path

    def _ended(self, sol, path: list[State], support):
        """``sol`` ending on the path's end keyframe (:meth:`path_end`).

        Keeps the landing joints Theta2 found the pose with (Theta3's start).
        """
        land = sol.state.info.get("landing")
        sol.state = self.path_end(path, support)
        if land is not None:
            sol.state.info["landing"] = land
        return sol

    def body_path(self, state: State, sol, again, u_f, u_n):
        """(solution, samples, why) of the body move from ``state`` to ``sol.state``.

        The leaf's samples (eq. 6b); where they fail :meth:`path_problem`, ``again(rolled)``
        solves the move once more from the stance feet where the path left them, and a
        leg link sweeping an edge gets a via pose (:meth:`_via_path`). ``why`` is "" for a
        path that passes. ``sol.state.support`` must be set.
        """
        support = sol.state.support
        path = interpolate_leaf(
            self.robot, self.terrain, state, sol.state, self.body_samples_at(state)
        )
        why = self.path_problem(path)
        if why:
            # the stance feet roll along the path (mm; more when the body pitches), so the
            # path ends on other feet than Theta2 placed its pose on: solve it again on the
            # rolled feet, and interpolate to that pose
            rolled = state.copy()
            rolled.feet_W = path[-1].feet_W.copy()
            second = again(rolled)
            self._count(second.problem.lower(), second.feasible)
            if second.feasible:
                second.state.support = support
                second.state.feet_W = state.feet_W.copy()
                path2 = interpolate_leaf(
                    self.robot, self.terrain, state, second.state, self.body_samples_at(state)
                )
                why2 = self.path_problem(path2)
                if not why2 or ("path margin" in why2) == ("path margin" in why):
                    sol, path, why = second, path2, why2
        if "path margin" in why:  # a leg link sweeps past an edge between two clear poses
            via_path = self._via_path(state, sol.state, path, u_f, u_n)
            if via_path is not None:
                why2 = self.path_problem(via_path)
                if not why2:
                    path, why = via_path, ""
        return sol, path, why

    def _via_path(self, start: State, end: State, path: list[State], u_f, u_n):
        """A body move through a via pose where ``path`` brings a leg link nearest the terrain.

        Beyond the paper: the leaf's straight line in exponential coordinates (eq. 6b) can
        sweep a thigh or shank past a step edge although both ends clear it. Theta1 (the
        COM held where the first failing sample has it, leg links clear by the keyframe margin)
        picks a via pose on the same leaf there; the move is then start -> via -> end.
        Returns the new path, or None when Theta1 finds no via pose.
        """
        links = leg_links(self.robot)
        worst = [
            float(
                links.path_margin(
                    self.terrain,
                    self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad),
                ).min()
            )
            for s in path
        ]
        k = next((i for i, m in enumerate(worst) if m < 0.0), int(np.argmin(worst)))
        probe = path[k].copy()
        probe.feet_W = start.feet_W.copy()
        support = end.support
        if support not in self._via_theta1:
            # the via pose is on four feet: no three-leg tip margin
            opts = replace(self.settings.theta, balance_margin_m=-np.inf)
            self._via_theta1[support] = Theta1(
                self.robot, self.terrain, support=support, options=opts, mu=self.mu
            )
        sol = self._via_theta1[support].solve(probe, self.check.com_W(path[k]), u_f, u_n)
        self._count("theta1", sol.feasible)
        if not sol.feasible:
            return None
        via = sol.state
        via.support = support
        n = self.body_samples_at(start)
        first = interpolate_leaf(self.robot, self.terrain, start, via, n)
        end2 = end.copy()
        end2.feet_W = first[-1].feet_W.copy()
        second = interpolate_leaf(self.robot, self.terrain, first[-1], end2, n)
        return first + second[1:]

    def blocks_passage(self, touch: State, leg: int) -> bool:
        """Whether ``leg``, landed as in ``touch`` next to a tall edge, stops the body passing.

        Beyond the paper: a hind foot a few centimetres before a barrier, its knee pointing
        ahead, lands clear, but the body cannot then move over it (the shank sweeps into
        the barrier), and its other knee branch is out of its joint limits there: the walk
        is stuck (barrier75mm, recursive, 0.7 torque fraction). The leg is judged on its
        branch with the body ``PASSAGE_STRIDES`` of a stride further along, at its nominal
        height over the ground or up to ``PASSAGE_RAISES_M`` higher: blocked where at some
        such distance the leg reaches its foot and no height keeps its links (away from
        the foot) ``PASSAGE_CLEARANCE_M`` clear. Only next to a tall edge (as
        :meth:`_other_knee_landing`).
        """
        if not self._next_to_tall_edge(touch.feet_W[leg], leg):
            return False
        R = touch.base_rotation_W
        th = touch.joints_rad[leg]
        knee = self.kin.knee_direction(leg, th)
        centre = R @ self.kin.foot_B(leg, th) + touch.base_position_W
        ahead = R[:, 0].copy()
        ahead[2] = 0.0
        ahead /= max(float(np.linalg.norm(ahead)), 1e-9)
        for strides in PASSAGE_STRIDES:
            base = touch.base_position_W + ahead * strides * self.stride_m()
            ground = float(self.terrain.height(*base[:2])) + nominal_height_m(self.robot)
            reached = False
            for dz in PASSAGE_RAISES_M:
                moved = touch.copy()
                moved.base_position_W = np.array([base[0], base[1], ground + dz])
                got = self._far_link_clearance(moved, leg, centre, th, knee)
                if got is None:
                    continue
                reached = True
                if got[0] >= PASSAGE_CLEARANCE_M:
                    break
            else:
                if reached:
                    return True
        return False

    def _far_link_clearance(self, s: State, leg: int, centre_W, th, knee: int):
        """(clearance [m], joints) of ``leg``'s links away from its foot, or None.

        At body pose ``s`` with the foot centre at ``centre_W`` on knee branch ``knee``
        (``th``: the IK's reference); None where the leg cannot reach it so. The least
        clearance of the leg's link points farther than ``KNEE_CHOICE_FOOT_ZONE_M`` from
        the foot (near it the shank always comes close to the ground); inf if there are none.
        """
        R = s.base_rotation_W
        ik = self.kin.ik_leg(leg, R.T @ (centre_W - s.base_position_W), reference_rad=th, knee=knee)
        if not ik.reachable or ik.knee_flipped:
            return None
        links = leg_links(self.robot)
        j = s.joints_rad.copy()
        j[leg] = ik.joints_rad
        q = self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, j)
        gap, pts = links.point_clearances(self.terrain, q)
        mine = np.array([links.capsules[c].leg == leg for c in links.owner])
        far = mine & (np.linalg.norm(pts - centre_W, axis=1) >= KNEE_CHOICE_FOOT_ZONE_M)
        return (float(gap[far].min()) if far.any() else np.inf), ik.joints_rad

    def _next_to_tall_edge(self, foot_W, leg: int) -> bool:
        """Terrain within half ``leg``'s reach ``KNEE_CHOICE_EDGE_M`` above ``foot_W``."""
        foot = np.asarray(foot_W, float).reshape(3)
        r = 0.5 * float(self.robot.reach_m[leg])
        u = np.linspace(-r, r, 15)
        X, Y = np.meshgrid(foot[0] + u, foot[1] + u)
        near = np.hypot(X - foot[0], Y - foot[1]) <= r
        H = np.asarray(self.terrain.height_sharp(X[near], Y[near]), float)
        return float(H.max()) >= float(foot[2]) + KNEE_CHOICE_EDGE_M

    def swing(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        step_m: float,
        target_W=None,
        knee: int | None = None,
    ):
        """Theta3 for ``leg`` toward ``target_W`` (default Lambda_t); returns (solution, samples).

        A swing path that leaves the leg's reach is retried once with half the clearance.
        ``knee`` (+1 forward, -1 rearward: :meth:`LegKinematics.knee_direction`): the knee
        branch to land on (a precomputed plan's, 8.3), instead of
        :meth:`_other_knee_landing`'s choice; the swing fails where it cannot land there
        (the feedback then tries a body nearer the support's incentre).
        """
        if target_W is None:
            target_W = lambda_t(self.robot, self.terrain, state, leg, tau, step_m=step_m)
        lifted = state.copy()
        lifted.stratum = leg + 1
        x0 = None
        land = state.info.get("landing")  # (target, joints) of a landing-ready Theta2
        if land is not None and np.allclose(land[0], target_W, atol=1e-9):
            x0 = np.concatenate([land[1], np.asarray(target_W, float)[:2]])
        for radius in (TARGET_RADIUS_M, WIDE_TARGET_RADIUS_M):
            sol = self.theta3(leg).solve(lifted, target_W, x0=x0, target_radius_m=radius)
            self._count("theta3", sol.feasible)
            # near an edge the leg's links may forbid every foothold close to the target:
            # let the foot land farther (the edge test below still applies)
            near = ("leg_clearance", "target_radius")
            if sol.feasible or not any(sol.violations.get(k, 0.0) > 1e-6 for k in near):
                break
        if not sol.feasible:
            return sol, []
        touch = sol.state
        touch.support = tuple(range(4))
        # the target keeps EDGE_MARGIN_M from edges, the foot lands within TARGET_RADIUS_M
        hazard = foothold_hazard(
            self.terrain,
            touch.feet_W[leg],
            self.robot.foot_radius_m,
            self.mu,
            EDGE_MARGIN_M - TARGET_RADIUS_M,
            forward_W=reference_directions(tau, self.terrain, touch.feet_W[leg])[0],
        )
        if hazard:
            sol.feasible = False
            sol.diagnosis = f"foothold of {LEG_NAMES[leg]} has {hazard}"
            return sol, []
        other = self._other_knee_landing(touch, leg, knee)
        if other is not None:  # a knee over an edge: land on the branch that clears it
            path, why = self._joint_space_swing(lifted, other, leg)
            if not why:
                sol.state = self.path_end(path, tuple(range(4)))
                return sol, path
        if knee is not None and self.kin.knee_direction(leg, touch.joints_rad[leg]) != knee:
            # the branch asked for (a plan's) or none: the plan's next steps assume it
            sol.feasible = False
            sol.diagnosis = (
                f"swing of {LEG_NAMES[leg]}: no landing on the plan's knee branch from here"
                + (f" ({why})" if other is not None else " (out of reach on it)")
            )
            return sol, []
        clearance = self.swing_clearance_m(lifted, leg, touch.feet_W[leg])
        for clr in (clearance, 0.5 * clearance):
            path = interpolate_swing(
                self.robot,
                self.terrain,
                lifted,
                touch,
                self.swing_samples_at(lifted, leg, touch.feet_W[leg]),
                clr,
                swing_leg=leg,
            )
            why = self.path_problem(path)
            self._count("swing_ik", not why)
            if not why:
                sol.state = self.path_end(path, tuple(range(4)))
                return sol, path
            if "balance" in why:  # a lower swing does not move the COM less
                break
        if "balance" not in why:  # the foot's path is clear but a link is not: fold the leg
            path, why2 = self._joint_space_swing(lifted, touch, leg)
            if not why2:
                sol.state = self.path_end(path, tuple(range(4)))
                return sol, path
        sol.feasible = False
        sol.diagnosis = f"swing of {LEG_NAMES[leg]}: {why}"
        return sol, []

    def _joint_space_swing(self, lifted: State, touch: State, leg: int):
        """(samples, why): :func:`joint_space_swing` and the path checks ("" if executable)."""
        path = joint_space_swing(
            self.robot, self.terrain, lifted, touch, 2 * self.settings.swing_samples, leg
        )
        for sample in path or ():  # it passes an edge closely: slower (planner.motion.time_law)
            sample.info["over_edge"] = True
        why = "no path in the leg's joint space" if path is None else self.path_problem(path)
        self._count("swing_joint_space", not why)
        return path, why

    def _other_knee_landing(self, touch: State, leg: int, want: int | None = None) -> State | None:
        """``touch`` with ``leg`` on its other knee branch, where that clears an edge better.

        Beyond the paper: a leg that lands next to a tall edge with its knee over it (a
        hind leg before a barrier, whose knee points forward) is clear at touch-down, but
        the body moves that follow lower the knee onto the edge. Both branches are judged
        with the body ``KNEE_CHOICE_LOOKAHEAD`` of a stride further along (where the next
        moves take it; a whole stride leaves the reach of a leg at the back), also lowered
        to the nominal height over the ground (a raised body comes down), by the least
        clearance of the leg's links away from the foot (where the shank always comes
        near the ground): the other branch is taken when the leg's own one comes within
        ``KNEE_CHOICE_CLEARANCE_M`` there and the other is ``KNEE_CHOICE_GAIN_M`` clearer.
        The swing then changes branch in the air (:func:`joint_space_swing`). Only next
        to a tall edge (terrain within half the leg's reach ``KNEE_CHOICE_EDGE_M`` above
        the foothold: a barrier, a tall riser): on stepping stones it flipped knees over
        their few centimetres of height and the open-loop walk fell.

        ``want`` (+1/-1): the branch to land on, chosen before (the precomputed plan's, 8.3:
        from a state a few millimetres off, step10cm's feedback landed HR on the other
        branch, and the plan's next steps found no body move from there); None when
        ``touch`` is on it or the leg cannot reach its foot on it.
        """
        if want is not None:
            th = touch.joints_rad[leg]
            if self.kin.knee_direction(leg, th) == int(want):
                return None
            ik = self.kin.ik_leg(leg, self.kin.foot_B(leg, th), reference_rad=th, knee=int(want))
            if not ik.reachable or ik.knee_flipped:
                return None
            return _with_leg_joints(touch, leg, ik.joints_rad)
        R = touch.base_rotation_W
        th = touch.joints_rad[leg]
        centre = R @ self.kin.foot_B(leg, th) + touch.base_position_W
        ahead = R[:, 0].copy()
        ahead[2] = 0.0
        ahead *= KNEE_CHOICE_LOOKAHEAD * self.stride_m() / max(float(np.linalg.norm(ahead)), 1e-9)
        moved = touch.copy()
        moved.base_position_W = touch.base_position_W + ahead
        lowered = moved.copy()  # ... and at the nominal height over the ground there
        lowered.base_position_W[2] = min(
            moved.base_position_W[2],
            float(self.terrain.height(*moved.base_position_W[:2])) + nominal_height_m(self.robot),
        )

        def clearance(knee: int) -> tuple[float, np.ndarray | None]:
            """Least far clearance of the leg on branch ``knee`` at the three body poses."""
            out, joints = np.inf, None
            for s in (touch, moved, lowered):
                got = self._far_link_clearance(s, leg, centre, th, knee)
                if got is None:
                    if s is touch:
                        return -np.inf, None
                    continue  # out of reach there: the body will not go there
                joints = got[1] if joints is None else joints
                out = min(out, got[0])
            return out, joints

        if not self._next_to_tall_edge(touch.feet_W[leg], leg):
            return None
        own = self.kin.knee_direction(leg, th)
        have, _ = clearance(own)
        if have >= KNEE_CHOICE_CLEARANCE_M:
            return None
        better, joints = clearance(-own)
        if joints is None or better < have + KNEE_CHOICE_GAIN_M:
            return None
        return _with_leg_joints(touch, leg, joints)

    def _body_gaps_m(self, path: list[State]) -> NDArray[np.float64]:
        """(N, K) heights [m] of the body's bottom-face points over the sharp terrain."""
        pts_B = self._bottom_B
        pts = np.array([pts_B @ s.base_rotation_W.T + s.base_position_W for s in path])
        return pts[..., 2] - np.asarray(self.terrain.height_sharp(pts[..., 0], pts[..., 1]))

    def path_problem(self, path: list[State]) -> str:
        """Why a sampled leaf path is not executable, or "": reach and balance per sample.

        Keyframes are feasible by construction, the samples between them are not: a leg
        can run out of reach mid-way, the body box can dip onto the sharp terrain (its
        bottom face is checked on a 5 mm grid), a thigh or shank can pass through an edge
        (:meth:`planner.body.links.LegLinks.path_margin`: 1 mm + 1.5 degrees x the distance to
        where the leg is held), and the COM
        moves (the body along eq. 6b, the swing leg's own mass) so that it can leave the
        support, or needs joint torques near the servos' limits (``TORQUE_FRACTION`` of
        the URDF effort in the distribution the feed-forward commands,
        :mod:`planner.body.torques`: a saturated servo cannot track). Every
        sample is checked with IK and the exact friction-cone test
        (:func:`planner.body.statics.static_feasibility`), with a margin of
        ``settings.balance_margin_frac`` x m g; on three legs the COM also stays
        ``planner.body.stability.PATH_BALANCE_MARGIN_M`` inside the support triangle. A start
        that already lacks a clearance or torque margin, or has a leg out of reach (a
        measured state, 8.3: a stretched leg whose foot rolled), is accepted; the path may
        not lose more (the IK miss may only shrink until the leg is back in reach).
        """
        from planner.body.statics import static_feasibility

        mg = self.robot.total_mass_kg * GRAVITY_M_S2
        need = self.settings.balance_margin_frac * mg
        miss = 0.0  # a start out of reach (a measured state, 8.3): no farther out after it
        for k, s in enumerate(path):
            if not s.info.get("ik_ok", True):
                err = float(s.info.get("ik_error_m", np.inf))
                if k == 0 or err <= miss + 1e-6:
                    miss = err if k == 0 else min(miss, err)
                    continue
                legs = ", ".join(LEG_NAMES[i] for i in s.info.get("unreachable_legs", []))
                return f"sample {k} of the path leaves the reach of {legs or 'a leg'}"
            miss = 0.0
        gaps = self._body_gaps_m(path)
        # a measured start may lack the margin: the path must not lose more
        body_floor = max(min(BODY_CLEARANCE_M, float(gaps[0].min()) - START_SLACK_M), 0.0)
        for k, gap in enumerate(gaps):
            if float(gap.min()) < body_floor:
                return (
                    f"the body passes {float(gap.min()) * 1000:.1f} mm above the terrain at "
                    f"sample {k} of the path (less than {BODY_CLEARANCE_M * 1000:.0f} mm)"
                )
        # stance feet roll as their shanks turn: at the path's end none rolled into an
        # edge (a riser); a measured start may already touch one, the path no deeper
        end, start = path[-1], path[0]
        stance = np.flatnonzero(end.in_contact)
        if len(stance):
            cut = self._foot_cut_m(end, stance)
            allowed = np.maximum(self._foot_cut_m(start, stance), 0.0) + FOOT_CUT_TOL_M
            j = int(np.argmax(cut - allowed))
            if cut[j] > allowed[j]:
                return (
                    f"the {LEG_NAMES[stance[j]]} foot rolls {cut[j] * 1000:.1f} mm into an edge "
                    "of the terrain on the path"
                )
        links = leg_links(self.robot)
        qs = [
            self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad) for s in path
        ]
        swings = [[i for i in range(4) if not s.in_contact[i]] for s in path]
        shorts, bares = links.path_margins(self.terrain, qs, swings, scales=(1.0, 0.0))
        # as for the body: not below what the start already has; nor touching deeper
        floor = np.minimum(shorts[0] - START_SLACK_M, 0.0)
        bare_floor = np.minimum(bares[0] - START_SLACK_M, 0.0)
        for k, (short, bare) in enumerate(zip(shorts, bares, strict=True)):
            c = int(np.argmin(short - floor))
            if short[c] < floor[c]:
                return (
                    f"the {links.describe(c)} comes {-short[c] * 1000:.1f} mm nearer the terrain "
                    f"than its path margin at sample {k} of the path"
                )
            if short.min() < 0.0:  # inside the margin, as the measured start: not touching
                c = int(np.argmin(bare - bare_floor))
                if bare[c] < bare_floor[c]:
                    return f"the {links.describe(c)} touches the terrain at sample {k} of the path"
        why = self._between_samples(path, qs, links, bares)
        if why:
            return why
        coms = [self.check.com_W(s) for s in path]  # Pinocchio, once per sample
        for k, s in enumerate(path):
            sup = _holding_legs(path, k)
            if len(sup) != 3:
                continue
            tip = support_margin_m(s.feet_W[sup], coms[k])
            if tip < PATH_BALANCE_MARGIN_M:
                return (
                    f"the COM is {tip * 1000:.1f} mm inside the support triangle at sample "
                    f"{k} of the path (< {PATH_BALANCE_MARGIN_M * 1000:.0f} mm: a tip-over "
                    "risk)"
                )
        # every sample's feet in one terrain pass, for the balance and the torques
        normals = np.asarray(self.terrain.normal(np.array([s.feet_W for s in path])), float)
        for k, s in enumerate(path[1:-1], start=1):
            sup = np.flatnonzero(s.in_contact)
            res = static_feasibility(
                s.feet_W,
                coms[k],
                self.robot.total_mass_kg,
                sup,
                self.mu,
                normals[k],
                with_com_margin=False,
            )
            s.info["margin_N"] = float(res.margin_N)  # the time law's floor (body_offsets_s)
            if not res.margin_N >= need:  # nan (solver failure) fails too
                return (
                    f"balance lost at sample {k} of the path (friction-cone margin "
                    f"{res.margin_N:.2f} N < {need:.2f} N): the COM leaves the support"
                )
        ceiling = TORQUE_FRACTION
        for k, (s, q) in enumerate(zip(path, qs, strict=True)):
            sup = _holding_legs(path, k)
            tq = self.torques.solve(q, sup, self.mu, normals[k], least_squares=True)
            if k == 0 and np.isfinite(tq.ratio):  # a measured start: no more than it needs
                ceiling = max(TORQUE_FRACTION, min(tq.ratio, MAX_START_TORQUE_FRACTION))
            if not tq.ratio <= ceiling:
                j = max(tq.worst_joint, 0)
                return (
                    f"joint {self.robot.joint_names[j]} needs {100 * tq.ratio:.0f} % of its "
                    f"effort limit at sample {k} of the path (more than "
                    f"{100 * TORQUE_FRACTION:.0f} %)"
                )
            bound = self.settings.theta.sway_stiffness
            if k == len(path) - 1 and len(sup) == 3 and bound is not None:
                # the three-leg stance the path ends in holds on the servos (Theta2's
                # bound, on the rolled feet the path ends on)
                sway = sway_stiffness_of(self.robot)
                have = sway.stance(
                    s.base_position_W, s.base_rotation_W, s.joints_rad, sup,
                    np.nan_to_num(tq.torques_nm),
                ).least  # fmt: skip
                need = sway.bound_n_per_m(bound)
                if not have >= need:
                    return (
                        f"the three-leg stance at the end of the path sways: stiffness "
                        f"{have:.0f} N/m on the servos (< {need:.0f} N/m; -inf: a singular "
                        "support leg)"
                    )
        return ""

    def _between_samples(self, path: list[State], qs: list, links, bares: list) -> str:
        """Why the motion between two samples passes a leg link through the terrain, or "".

        The executor interpolates the joints linearly between samples; where a joint moves
        more than ``BETWEEN_SAMPLES_RAD`` in one interval (a knee flipping at lift-off) the
        leg sweeps unchecked: its links are checked every ``BETWEEN_STEP_RAD`` there, and
        may come no nearer the terrain than at the interval's two ends or 0. gen:5's plan
        flipped a front knee 144 degrees between two clear samples; the shank passed 16 mm
        through a stone between them, and the robot tipped over in MuJoCo.
        ``bares`` (N, C): the links' clearance bounds at the samples (path_problem's); the
        configurations between samples are measured in one terrain query per set of legs
        swept.
        """
        sweeps = []  # (k, legs swept, swing legs, configurations between k and k + 1)
        for k in range(len(path) - 1):
            a, b = path[k], path[k + 1]
            leg_jump = np.max(np.abs(b.joints_rad - a.joints_rad), axis=1)  # (4,) [rad]
            jump = float(leg_jump.max())
            if jump <= BETWEEN_SAMPLES_RAD:
                continue
            swing = [i for i in range(4) if not (a.in_contact[i] and b.in_contact[i])]
            # a leg moving less than one sweep step is within it of its ends (a stance leg
            # beside a swing does not move at all): only the others are swept
            legs = tuple(int(i) for i in np.flatnonzero(leg_jump > BETWEEN_STEP_RAD))
            m = int(np.ceil(jump / BETWEEN_STEP_RAD))
            inner = [between_q(qs[k], qs[k + 1], u) for u in np.arange(1, m) / m]
            sweeps.append((k, legs, swing, inner, jump))
        measured: dict[int, np.ndarray] = {}
        for legs in {legs for _, legs, _, _, _ in sweeps}:
            group = [sw for sw in sweeps if sw[1] == legs]
            qs_all = [q for sw in group for q in sw[3]]
            swings = [sw[2] for sw in group for _ in sw[3]]
            out = links.path_margins(self.terrain, qs_all, swings, scales=(0.0,), legs=legs)[0]
            at = 0
            for sw in group:
                measured[sw[0]] = out[at : at + len(sw[3])]
                at += len(sw[3])
        for k, _, _, _, jump in sweeps:
            floor = np.minimum(np.minimum(bares[k], bares[k + 1]), 0.0) - START_SLACK_M
            for bare in measured[k]:
                c = int(np.argmin(bare - floor))
                if bare[c] < floor[c]:
                    return (
                        f"the {links.describe(c)} passes {-bare[c] * 1000:.1f} mm through the "
                        f"terrain between samples {k} and {k + 1} of the path (its joints move "
                        f"{jump:.2f} rad there)"
                    )
        return self._feet_between_samples(path, sweeps)

    def _feet_between_samples(self, path: list[State], sweeps: list) -> str:
        """Why a swinging foot's sphere passes through the terrain between samples, or "".

        The feet of :meth:`_between_samples`' sweeps (legs not down at both ends), at the
        same configurations: the sphere may cut the sharp terrain no deeper than at the
        interval's ends or ``FOOT_CUT_TOL_M`` (the check's). A swing out of a 12 cm trench
        flipped a front knee 140 degrees between two samples 15 and 31 mm clear; the
        straight-line joints between them put the foot 7 mm into the trench's floor, and
        the open-loop walk fell in MuJoCo (the links passed).
        """
        rho = self.robot.foot_radius_m
        for k, legs, swing, inner, jump in sweeps:
            feet = [i for i in swing if i in legs]
            if not feet or not inner:
                continue
            centres = []
            for q in inner:
                R = rotation_from_quat(np.asarray(q[3:7], float))
                joints = self.robot.joints_from_q(q)
                centres += [R @ self.kin.foot_B(i, joints[i]) + q[:3] for i in feet]
            cut = sphere_penetration_m(self.terrain, np.array(centres), rho)
            worst = cut.reshape(len(inner), len(feet)).max(axis=0)
            ends = np.maximum(self._foot_cut_m(path[k], feet), self._foot_cut_m(path[k + 1], feet))
            allowed = np.maximum(ends, 0.0) + FOOT_CUT_TOL_M
            j = int(np.argmax(worst - allowed))
            if worst[j] > allowed[j]:
                return (
                    f"the {LEG_NAMES[feet[j]]} foot passes {worst[j] * 1000:.1f} mm through the "
                    f"terrain between samples {k} and {k + 1} of the path (its joints move "
                    f"{jump:.2f} rad there)"
                )
        return ""

    def _foot_cut_m(self, state: State, legs) -> np.ndarray:
        """How far the sharp terrain cuts into ``legs``' foot spheres at ``state`` [m]."""
        R, p = state.base_rotation_W, state.base_position_W
        centres = np.array([R @ self.kin.foot_B(i, state.joints_rad[i]) + p for i in legs])
        return sphere_penetration_m(self.terrain, centres, self.robot.foot_radius_m)

    def path_end(self, path: list[State], support: tuple[int, ...]) -> State:
        """The last sample of a path as the keyframe it ends on (:func:`end_keyframe`).

        The stance feet roll along the path (:mod:`planner.body.rolling`), so the path ends with
        the keyframe's pose on feet a few millimetres from the Theta solution's; its joints
        are the path's (IK onto the rolled feet) and its forces are solved again for them.
        """
        end = end_keyframe(self.robot, path, support, self.check.com_W(path[-1]))
        path[-1] = end
        return end

    def stride_m(self) -> float:
        """Stride of Lambda_t [m]: ``settings.step_m`` or 0.35 x the shortest leg reach."""
        st = self.settings
        return st.step_m if st.step_m is not None else 0.35 * float(np.min(self.robot.reach_m))

    def stride_at(self, state: State, leg: int, tau: Trajectory) -> float:
        """The stride of ``leg``'s next step [m]: ``level_stride`` x reach on level ground.

        Elsewhere, and without ``level_stride``, :meth:`stride_m`. Level: the terrain
        (sharp heights, every ``LEVEL_GRID_M``) under the swing's track from the foot to the
        long stride's target, widened by ``LEVEL_WIDTH_M`` each side, and under the stance
        feet lies within ``LEVEL_TOL_M`` of the plane of the four feet, and that plane is
        within ``LEVEL_SLOPE`` of horizontal. A long stride stretches the legs between the
        feet: on steps, stairs and slopes that left stances the servos could not hold on
        three legs (step5cm and stairs stalled with 12 cm strides everywhere); on level
        ground it halves the steps of a walk.
        """
        short = self.stride_m()
        if self.settings.level_stride is None:
            return short
        long = self.settings.level_stride * float(np.min(self.robot.reach_m))
        if long <= short:
            return short
        target = self.stride_target(state, leg, tau, long)
        return long if self._level_track(state, leg, target) else short

    def level_under(self, state: State) -> bool:
        """Whether the ground under the four feet is level (:meth:`stride_at`'s test).

        The terrain every ``LEVEL_GRID_M`` over the feet's bounding box, and the feet,
        within ``LEVEL_TOL_M`` of the feet's plane, that plane within ``LEVEL_SLOPE``.
        """
        feet = np.asarray(state.feet_W, float).reshape(4, 3)
        lo, hi = feet[:, :2].min(axis=0), feet[:, :2].max(axis=0)
        xs = np.arange(lo[0], hi[0] + LEVEL_GRID_M, LEVEL_GRID_M)
        ys = np.arange(lo[1], hi[1] + LEVEL_GRID_M, LEVEL_GRID_M)
        pts = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
        return self._on_feet_plane(feet, pts)

    def swing_clearance_m(self, state: State, leg: int, touch_W) -> float:
        """The swing height [m] of ``leg`` from ``state`` to ``touch_W``.

        ``level_clearance_m`` where the ground under the track is level (:meth:`stride_at`'s
        test), else ``clearance_m`` (default:
        :func:`planner.motion.interpolate.default_clearance_m`).
        """
        st = self.settings
        clearance = st.clearance_m or default_clearance_m(self.robot)
        if st.level_clearance_m is None or not self._level_track(state, leg, touch_W):
            return clearance
        return float(st.level_clearance_m)

    def swing_samples_at(self, state: State, leg: int, touch_W) -> int:
        """Samples of ``leg``'s swing: ``level_swing_samples`` over level ground."""
        st = self.settings
        if st.level_swing_samples is None or not self._level_track(state, leg, touch_W):
            return int(st.swing_samples)
        return int(st.level_swing_samples)

    def body_samples_at(self, state: State) -> int:
        """Samples of a body move from ``state``: ``level_body_samples`` over level ground."""
        st = self.settings
        if st.level_body_samples is None or not self.level_under(state):
            return int(st.body_samples)
        return int(st.level_body_samples)

    def _level_track(self, state: State, leg: int, touch_W) -> bool:
        """Whether the ground under ``leg``'s track to ``touch_W`` is level (stride_at's)."""
        feet = np.asarray(state.feet_W, float).reshape(4, 3)
        return self._on_feet_plane(feet, _track_xy(feet[leg], touch_W))

    def _on_feet_plane(self, feet: np.ndarray, pts: np.ndarray) -> bool:
        """The feet's plane is within LEVEL_SLOPE, the terrain at ``pts`` and the feet on it."""
        grad, centre = support_plane_W(feet)
        if float(np.linalg.norm(grad)) > LEVEL_SLOPE:
            return False
        pts = np.vstack([pts, feet[:, :2]])
        z = np.asarray(self.terrain.height_sharp(pts[:, 0], pts[:, 1]), float).reshape(-1)
        plane = centre[2] + (pts - centre[:2]) @ grad
        return float(np.max(np.abs(z - plane))) <= LEVEL_TOL_M

    def step(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        step_m: float,
        shrink: float | None = None,
        target_W=None,
        try_others: bool = True,
        body_hint: State | None = None,
        knee: int | None = None,
    ) -> Step:
        """One step of ``leg`` from ``state``: body move (swing-ready), swing, placement.

        The body move is first asked to keep ``leg`` within reach of its next foothold
        (Theta2's swing-ready constraint); if that is infeasible, the paper's plain Theta2.
        When that foothold fails (no landing-ready body pose, or no swing), up to
        ``OTHER_FOOTHOLDS`` others of the leg's reachable, safe region are tried
        (:meth:`other_footholds`, issue 15). A failed placement keeps the body move
        (``Step.moved``) of the first attempt: the robot stands safely on three legs there.
        A foothold that would leave the gait's next leg no stance to swing from
        (:meth:`leaves_no_support`) is tried after those around the leg's nominal
        placement that do not. With ``foothold_lookahead`` a foothold after which the next
        leg finds no body move is passed over for the next one that leaves it one (the
        first such step is returned when none does). ``shrink`` overrides
        ``settings.shrink`` of Lambda_c.
        ``target_W``: the foothold to try first (a terrain point, world frame; e.g. a
        precomputed plan's), instead of Lambda_t's; ``try_others`` False: no other
        foothold is tried. ``body_hint``: a body pose near the one expected for the first
        foothold (the precomputed plan's, feedback 8.3), Theta2's last starting point.
        ``knee``: the knee branch the leg lands on (the precomputed plan's, :meth:`swing`).
        """
        args = (state, leg, tau, step_m, shrink, target_W, try_others, body_hint, knee)
        first = self._step_once(*args)
        if first.ok or not self.settings.follow_support or self._sink:
            return first
        # back off (issue 13 item 5): the same step with the body lowered wherever a leg
        # would be stretched (:meth:`_reach_sink_m`); kept only when it succeeds
        self._sink = True
        try:
            low = self._step_once(*args)
        finally:
            self._sink = False
        return low if low.ok else first

    def _step_once(
        self,
        state: State,
        leg: int,
        tau: Trajectory,
        step_m: float,
        shrink,
        target_W,
        try_others,
        body_hint: State | None = None,
        knee: int | None = None,
    ) -> Step:
        """One attempt of :meth:`step` at the body height in force."""
        if target_W is not None:
            target = np.asarray(target_W, float).reshape(3)
        else:
            target, _ = self.foothold_target(state, leg, tau, step_m, shrink)
        order = [target]  # the footholds to try, in order
        extended = False  # the other footholds are in ``order``
        if try_others and self.leaves_no_support(state, leg, target):
            # a dead end for the next leg: first the footholds around the nominal placement
            # (wider sideways: the stance width may have to change) that leave it a stance
            order = self.other_footholds(
                state, leg, tau, target, shrink,
                centre_W=self.stride_target(state, leg, tau, step_m, shrink),
                max_lateral_m=DEAD_END_LATERAL_M,
                keep=lambda c: not self.leaves_no_support(state, leg, c),
            ) + [target]  # fmt: skip
        first = None  # the first failure, reported when no foothold works
        dead_end = None  # the first step made that leaves the next leg no body move
        k = 0
        while k < len(order):
            target = order[k]
            hint = body_hint if k == 0 else None
            sol2, body_path = self._body_move_once(state, leg, tau, target, shrink, hint)
            if k == 0 and not sol2.feasible:
                # the paper's plain Theta2 (no swing-ready pose) for the first foothold
                sol2, body_path = self._body_move_once(state, leg, tau, None, shrink, hint)
            if not sol2.feasible:
                step = Step(leg, False, state, None, None, [], [], "body_move", sol2.diagnosis)
            else:
                sol3, swing_path = self.swing(
                    sol2.state, leg, tau, step_m, target, knee if k == 0 else None
                )
                if sol3.feasible and self.foothold_passage and self.blocks_passage(sol3.state, leg):
                    # a landing the body cannot pass over fails like one out of reach
                    sol3.feasible = False
                    sol3.diagnosis = (
                        f"swing of {LEG_NAMES[leg]}: standing there, its links would meet "
                        "the edge ahead as the body passes over the foot"
                    )
                if sol3.feasible:
                    made = Step(leg, True, state, sol2.state, sol3.state, body_path, swing_path)
                    if (
                        not try_others
                        or not self.foothold_lookahead
                        or self.next_leg_can_move(sol3.state, leg, tau, shrink)
                    ):
                        return made
                    dead_end = dead_end or made
                    step = Step(
                        leg, False, state, sol2.state, None, body_path, [], "foot_placement",
                        "the foothold leaves the next leg no body move",
                    )  # fmt: skip
                else:
                    step = Step(
                        leg, False, state, sol2.state, None, body_path, [], "foot_placement",
                        sol3.diagnosis,
                    )  # fmt: skip
            first = first or step
            if "balance_margin" in step.diagnosis and step.phase == "body_move" and k == 0:
                break  # the COM cannot shift onto the other three legs: no foothold helps
            if not try_others:
                break
            if not extended:
                order += self.other_footholds(state, leg, tau, target, shrink)
                extended = True
            k += 1
        return dead_end or first

    def _body_move_once(self, state: State, leg: int, tau: Trajectory, target, shrink, hint):
        """:meth:`body_move`, remembering its failures for this run.

        A body move is a deterministic function of its inputs (Theta2 starts from the
        state, not from its last solve), and the recursive planner (8.5) asks for the same
        failing one again with every ambition that keeps the body target (the plain pose
        of the first foothold, the other footholds): barrier9cm spent 2-3 s per repeat.
        """
        arrays = [state.base_position_W, state.base_quaternion_xyzw, state.joints_rad,
                  state.feet_W]  # fmt: skip
        if target is not None:
            arrays.append(np.asarray(target, float))
        if hint is not None:
            arrays += [hint.base_position_W, hint.base_quaternion_xyzw, hint.joints_rad]
        key = (leg, target is None, hint is None, shrink, self._sink, id(tau)) + tuple(
            np.ascontiguousarray(a, float).tobytes() for a in arrays
        )
        failed = self._failed_moves.get(key)
        if failed is not None:
            return failed, []
        sol, path = self.body_move(state, leg, tau, target, shrink, hint)
        if not sol.feasible:
            if len(self._failed_moves) >= FAILED_MOVES_KEPT:
                self._failed_moves.clear()
            self._failed_moves[key] = sol
        return sol, path

    def next_leg_can_move(self, state: State, leg: int, tau: Trajectory, shrink=None) -> bool:
        """Whether the gait's next leg finds a body move (plain Theta2) after ``leg``'s step.

        Beyond the paper: a one-step look-ahead of the foothold choice. Climbing a step the
        front feet reach far ahead onto it while the hind feet stay below; a foothold that
        leaves no body pose keeping the next leg's stance within reach and balance is a
        dead end (the soft planner would stall there). When every foothold tried is one,
        :meth:`step` returns the first that was made.
        """
        return self.legs_can_move(state, [self._next_leg(leg)], tau, shrink)

    def legs_can_move(self, state: State, legs, tau: Trajectory, shrink=None) -> bool:
        """Whether each of ``legs`` finds a body move onto the other three (plain Theta2)."""
        for nxt in legs:
            rc = self.body_target(state, nxt, shrink, tau=tau)
            u_f, u_n = self.body_directions(tau, state, rc, nxt)
            sol = self.theta2(tuple(i for i in range(4) if i != nxt)).solve(state, rc, u_f, u_n)
            self._count("theta2_lookahead", sol.feasible)
            if not sol.feasible:
                return False
        return True

    def _next_leg(self, leg: int) -> int:
        """The leg after ``leg`` in ``settings.gait``."""
        gait = list(self.settings.gait or CRAWL)
        return gait[(gait.index(leg) + 1) % len(gait)] if leg in gait else (leg + 1) % 4

    def leaves_no_support(self, state: State, leg: int, foothold_W) -> bool:
        """Whether ``leg`` on ``foothold_W`` leaves the gait's next leg no stance to swing from.

        The next leg of ``settings.gait`` swings on the other three feet; when their
        triangle's inradius is below ``BALANCE_MARGIN_M`` no COM keeps Theta2's balance
        margin on it (e.g. both front feet on one stepping stone: the hind legs can no
        longer step). Beyond the paper: a one-step look-ahead of the foothold choice.
        """
        nxt = self._next_leg(leg)
        feet = np.array(state.feet_W, float).reshape(4, 3)
        feet[leg] = np.asarray(foothold_W, float).reshape(3)
        return triangle_inradius_m(np.delete(feet, nxt, axis=0)) < BALANCE_MARGIN_M

    # ---- the loop ----------------------------------------------------------------------
    def plan(
        self,
        start_xy,
        goal_xy,
        tau: Trajectory | None = None,
        progress=None,
        start_state: State | None = None,
    ) -> LocalPlan:
        """Plan from ``start_xy`` (or ``start_state``) until the COM is at ``goal_xy``.

        ``progress(distance_m, steps)`` is called after each step. Ctrl-C (or SIGTERM
        under :class:`planner.core.interrupts.Interrupts`) stops planning and returns the plan
        so far (its message says so). Planning runs on one BLAS thread (threadpoolctl),
        whatever was imported first: the planner's matrices are small, and with numpy
        imported before the planner (``planner/__init__.py`` sets the default only for a
        numpy not yet loaded) two OpenBLAS threads spinning beside the overlap worker made
        rough2cm's planning 30.7 s instead of 22.5 s.
        """
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return self._plan(start_xy, goal_xy, tau, progress, start_state)

    def _plan(self, start_xy, goal_xy, tau, progress, start_state) -> LocalPlan:
        """:meth:`plan`'s work."""
        t_begin = time.perf_counter()
        self._failed_moves.clear()  # keyed by tau's id, which a new run may reuse
        if tau is None:
            tau = Trajectory.straight(start_xy, goal_xy, self.terrain, self.com_height_m())
        state = start_state if start_state is not None else self.initial_state(start_xy, tau)
        run = _Run(np.asarray(goal_xy, float)[:2], tau, t_begin, progress)
        worker = None
        if self.settings.overlap_worker and self.settings.swing_overlap > 0.0:
            from planner.planning.prefetch import OverlapWorker

            worker = OverlapWorker.start(self)
        walk = Walk(self, state, worker)
        try:
            try:
                message = self._run(walk, run)
            except KeyboardInterrupt:
                message = f"interrupted after {walk.steps} steps; the plan so far is kept"
            with interrupts.shielded():  # timed now (the overlaps), inside planning time
                walk.keyframes  # noqa: B018
        finally:
            if worker is not None:
                worker.close()
                walk.worker = None
        dist = self.distance_to_goal(walk.state, run)
        stats = (
            {
                "planner": self.name,
                "cycles": run.cycles,
                "steps": walk.steps,
                "planning_time_s": time.perf_counter() - t_begin,
                "overlap_worker_steps": 0 if worker is None else worker.used,  # timed by it
                "solves": {k: {"count": v[0], "feasible": v[1]} for k, v in self.stats.items()},
                "failures": self.failures[-50:],
            }
            | self.extra_stats
        )
        return LocalPlan(
            keyframes=walk.keyframes,
            samples=walk.samples,
            times=walk.times,
            reached_goal=dist <= self.settings.goal_tol_m,
            distance_to_goal_m=dist,
            message=message,
            stats=stats,
        )

    def _run(self, walk: Walk, run: _Run) -> str:  # pragma: no cover - abstract
        """Choose and record steps until done; return the reason planning stopped."""
        raise NotImplementedError

    def distance_to_goal(self, state: State, run: _Run) -> float:
        """Horizontal distance of the whole-body COM to the goal [m]."""
        return float(np.linalg.norm(self.check.com_W(state)[:2] - run.goal))

    def arrival(self, state: State, goal_xy, tau: Trajectory, nearest: bool = False):
        """A body move on all four feet bringing the COM over the goal: (end, path) or None.

        Beyond the paper, whose walk ends after a step: a crawl's keyframes put the COM
        inside a three-foot triangle, and a robot whose stride is long next to
        ``goal_tol_m`` (b1, laikago) stepped in place around the goal without a keyframe
        near it. Tried when the goal lies ``BALANCE_MARGIN_M`` inside the four feet's
        support polygon: Theta2 on S0 with all four legs, its target the goal at the
        height of the footholds' plane (:func:`support_body_target_W`), the path checked
        as every body move's. The robot ends standing on four feet over the goal. With
        ``nearest`` (the walk ends here: the COM is within ``goal_tol_m``), a goal nearer
        an edge than that is approached as far as the margin allows: the COM goes over the
        point of the inset polygon nearest to it (:func:`nearest_inside_point_W`;
        stepdown8cm's last keyframe had the goal 7 mm inside the polygon, the COM 4.8 cm
        from it), unless that point is within ``ARRIVAL_M / 2`` of the COM already or
        the goal is outside the feet.
        """
        feet = np.asarray(state.feet_W, float).reshape(4, 3)
        if polygon_margin_m(feet, goal_xy) < (0.0 if nearest else BALANCE_MARGIN_M):
            return None  # the goal is ahead of the feet: steps, not a body move
        goal = nearest_inside_point_W(feet, goal_xy, BALANCE_MARGIN_M)
        if goal is None:
            return None
        if np.linalg.norm(self.check.com_W(state)[:2] - goal) < 0.5 * ARRIVAL_M:
            return None
        probe = np.array([goal[0], goal[1], float(state.base_position_W[2])])
        u_f, u_n = reference_directions(tau, self.terrain, probe)
        z, u_n = support_body_target_W(
            self.robot, self.terrain, feet, goal, self.com_height_m(), u_f, u_n
        )
        rc = np.array([goal[0], goal[1], z])
        support = (0, 1, 2, 3)
        sol = self.theta2(support).solve(state, rc, u_f, u_n)
        self._count("theta2", sol.feasible)
        if not sol.feasible:
            return None
        sol.state.support = support
        path = interpolate_leaf(
            self.robot, self.terrain, state, sol.state, self.body_samples_at(state)
        )
        if self.path_problem(path):
            return None
        return self.path_end(path, support), path

    def stop_reason(self, walk: Walk, run: _Run, fails_in_row: int = 0) -> str:
        """Why planning must stop now ("" to go on): goal, cycles, time budget, stuck.

        Before the goal test, the :meth:`arrival` move is tried (once per keyframe) when
        the COM is farther than ``ARRIVAL_M`` from the goal, also within ``goal_tol_m``: a
        walk ends over its goal where the feet allow, not at the tolerance's edge (the
        feedback run of stepdown8cm ended 5.0 cm off, its plan 4.8 cm).
        """
        st = self.settings
        if interrupts.requested():
            return f"interrupted after {walk.steps} steps; the plan so far is kept"
        dist = self.distance_to_goal(walk.state, run)
        if dist > ARRIVAL_M and run.arrival_tried != walk.n_keyframes:
            run.arrival_tried = walk.n_keyframes
            moved = self.arrival(walk.state, run.goal, run.tau, dist <= st.goal_tol_m)
            if moved is not None:
                walk.add_body_move(*moved)
                dist = self.distance_to_goal(walk.state, run)
        if dist <= st.goal_tol_m:
            return f"reached the goal: COM {dist * 100:.1f} cm from it"
        if run.cycles >= st.max_cycles:
            return f"stopped after {run.cycles} cycles (max_cycles)"
        if time.perf_counter() - run.t_begin > st.time_budget_s:
            return f"stopped by the time budget ({st.time_budget_s:.0f} s)"
        if fails_in_row >= st.max_fails_in_row:
            return f"stuck: {fails_in_row} failed step attempts in a row; last: {run.last_failure}"
        if dist < run.best_dist_m - PROGRESS_M:
            run.best_dist_m, run.best_at = dist, run.cycles
        patience = st.no_progress_cycles * self.attempts_per_cycle()
        if run.cycles - run.best_at >= patience:
            return (
                f"stuck: no progress in {patience} cycles (the COM came no nearer "
                f"than {100 * run.best_dist_m:.0f} cm to the goal); last: {run.last_failure}"
            )
        return ""

    def attempts_per_cycle(self) -> int:
        """Step attempts (``run.cycles``) that count as one cycle of the no-progress stop."""
        return 1

    def failed(self, run: _Run, step: Step) -> None:
        """Log a failed step (kept in the plan's stats)."""
        phase = "body move" if step.phase == "body_move" else "foot placement"
        run.last_failure = f"{LEG_NAMES[step.leg]} {phase}: {step.diagnosis}"
        where = step.moved if step.moved is not None else step.start
        self._log_failure(run.cycles, step.leg, step.phase, where, step.diagnosis)

    def report(self, walk: Walk, run: _Run) -> None:
        """Call the progress callback."""
        if run.progress is not None:
            run.progress(self.distance_to_goal(walk.state, run), walk.steps)

    def _log_failure(self, cycle: int, leg: int, phase: str, state: State, why: str) -> None:
        self.failures.append(
            {
                "cycle": cycle,
                "leg": LEG_NAMES[leg],
                "phase": phase,
                "base_xy": np.round(state.base_position_W[:2], 3).tolist(),
                "why": why,
            }
        )

    def _swing_keyframe(self, path: list[State], leg: int, check) -> State:
        """The mid-swing configuration on S_leg, with its eq. 5 forces (3 stance feet)."""
        from planner.body.statics import equilibrating_forces

        mid = path[len(path) // 2].copy()
        mid.stratum = leg + 1
        mid.support = tuple(i for i in range(4) if i != leg)
        eq = equilibrating_forces(
            mid.feet_W, check.com_W(mid), self.robot.total_mass_kg, mid.support
        )
        mid.forces_W = None if eq.degenerate else eq.forces
        return mid

    def body_offsets_s(self, path: list[State]) -> NDArray[np.float64]:
        """Times [s] of a body path's samples 1.. after its first (:mod:`planner.motion.time_law`).

        The base accelerates at most ``body_accel_m_s2``, less where the stance cannot
        carry the inertial force with ``CARRIED_SHARE`` of its friction-cone margin to
        spare (:meth:`_carried_margin_N`); each interval is checked at its bound in the
        direction the law accelerates it, again if the law changes. Near the sharp terrain
        it goes at most its clearance beyond ``BODY_CLEARANCE_M`` over
        ``BODY_LAG_S`` x sqrt(s) (:func:`planner.motion.time_law.near_terrain_caps`).
        """
        from planner.body.robot_scale import time_scale
        from planner.motion.time_law import (
            BODY_LAG_S,
            body_profile,
            carried_accel_m_s2,
            near_terrain_caps,
        )

        if len(path) < 2:
            return np.zeros(0)
        st = self.settings
        gaps = self._body_gaps_m(path).min(axis=1)
        speed = np.minimum(
            st.body_speed_m_s,
            near_terrain_caps(
                np.minimum(gaps[:-1], gaps[1:]),
                BODY_CLEARANCE_M,
                BODY_LAG_S * time_scale(self.robot),
            ),
        )
        accel = st.body_accel_m_s2
        if st.level_body_accel_m_s2 is not None and self.level_under(path[0]):
            accel = st.level_body_accel_m_s2
        bound = np.full(len(path) - 1, float(accel))
        checked = np.zeros((len(bound), 2))  # magnitude verified, accelerating / braking
        margin = self._carried_margin_N(path)
        while True:
            dt, acc = body_profile(
                np.array([s.base_position_W for s in path]),
                [s.base_rotation_W for s in path],
                np.array([s.joints_rad.ravel() for s in path]),
                speed_m_s=speed,
                accel_m_s2=bound,
                arm_m=self._hip_arm_m(),
                vmax_rad_s=self._joint_speed_limits(),
            )
            todo = [
                (k, int(a < 0.0))
                for k, a in enumerate(acc)
                if abs(a) > checked[k, int(a < 0.0)] * (1 + 1e-9)
            ]
            if not todo:
                return np.cumsum(dt)
            for k, braking in todo:
                sign = -1.0 if braking else 1.0
                bound[k] = carried_accel_m_s2(
                    lambda a, k=k, sign=sign: margin(k, sign * a), bound[k], 0.0
                )
                checked[k, braking] = bound[k]

    def _carried_margin_N(self, path: list[State]):
        """margin(k, a): how far a body path's interval k carries accelerating by ``a``.

        The least, over the interval's two samples, of the friction-cone margin [N] on the
        contact feet with gravity g - a u (u the COM's direction over the interval;
        d'Alembert's inertial force, eq. 4), minus the margin that must remain: the
        path's own (``balance_margin_frac``) or ``CARRIED_SHARE`` of the sample's static
        margin, whichever is more; and the zero-moment point, the COM projected along
        g - a u (:func:`planner.body.stability.tip_margin_m`), inside the support polygon by
        ``CARRIED_SHARE`` of the COM's own tip margin at rest, or by
        ``PATH_BALANCE_MARGIN_M`` where that is more (at most the margin at rest): the
        friction margin stays wide while the far feet unload, and an arrival move braking
        at 1.5 m/s^2 toward an edge 2.9 cm from its COM (the ZMP 6 mm from it) tipped the
        robot over it in MuJoCo, as no swing keeping 21 mm ever did
        (:mod:`planner.body.stability`). The tip part counts in N as the horizontal force that
        would use what is left of it (m g x margin / COM height). And the joint torques of
        the commanded force distribution with gravity g - a u
        (:meth:`planner.body.torques.TorqueCheck.commanded_ratio_map`, on the legs that hold
        the sample: the three of the next swing at a move's end) use at most
        ``CARRIED_SHARE`` of the headroom between the sample's ratio at rest and
        ``TORQUE_FRACTION`` (counted as m g x the ratio): barrier9cm's recursive plan
        braked a 3.8 cm sway at 0.5 m/s^2 onto a three-leg stance with the FL knee at 72 %
        (88 % while braking), the knee saturated in MuJoCo and the robot fell; with that
        move taking twice as long it held.
        >= 0: the stance carries the motion.
        """
        from planner.body.stability import tip_margin_m
        from planner.body.statics import GRAVITY_W, static_feasibility
        from planner.motion.time_law import CARRIED_SHARE

        m = self.robot.total_mass_kg
        need = self.settings.balance_margin_frac * m * GRAVITY_M_S2
        g_W = np.asarray(GRAVITY_W, float)
        com = np.array([self.check.com_W(s) for s in path])
        d = np.diff(com, axis=0)
        u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        normals = [self.terrain.normal(s.feet_W) for s in path]

        def raw(j: int, g) -> float:
            s = path[j]
            res = static_feasibility(
                s.feet_W, com[j], m, np.flatnonzero(s.in_contact), self.mu, normals[j], g,
                with_com_margin=False,
            )  # fmt: skip
            return float(res.margin_N) if np.isfinite(res.margin_N) else -np.inf

        floors: dict[int, float] = {}
        tip_floors: dict[int, tuple[float, float]] = {}
        torque_maps: dict[int, tuple[np.ndarray, float]] = {}

        def tip(j: int, g) -> float:
            return tip_margin_m(path[j].feet_W[path[j].in_contact], com[j], g)

        def torque(j: int, g) -> float:
            """Torque headroom [N, as m g x the ratio] of sample j carrying gravity g."""
            if j not in torque_maps:
                s = path[j]
                q = self.robot.q_from(s.base_position_W, s.base_quaternion_xyzw, s.joints_rad)
                tmap = self.torques.commanded_ratio_map(
                    q, _holding_legs(path, j), normals[j]
                )  # fmt: skip
                still = float(np.abs(tmap @ g_W).max())
                torque_maps[j] = (tmap, still + CARRIED_SHARE * max(TORQUE_FRACTION - still, 0.0))
            tmap, allowed = torque_maps[j]
            return (allowed - float(np.abs(tmap @ g).max())) * m * GRAVITY_M_S2

        def margin(k: int, a: float) -> float:
            out = np.inf
            for j in (k, k + 1):
                if j not in floors:  # the static margin: path_problem's, if it solved it
                    still = path[j].info.get("margin_N")
                    still = raw(j, g_W) if still is None else still
                    floors[j] = max(need, CARRIED_SHARE * still)
                    feet = path[j].feet_W[path[j].in_contact]
                    height = max(float(com[j][2] - feet[:, 2].mean()), 1e-3)
                    tip0 = max(tip(j, g_W), 0.0)
                    floor = min(tip0, max(CARRIED_SHARE * tip0, PATH_BALANCE_MARGIN_M))
                    tip_floors[j] = (floor, m * GRAVITY_M_S2 / height)
                g = g_W - a * u[k]
                floor, per_m = tip_floors[j]
                out = min(out, raw(j, g) - floors[j], (tip(j, g) - floor) * per_m, torque(j, g))
            return out

        return margin

    def swing_offsets_s(self, path: list[State], leg: int) -> NDArray[np.float64]:
        """Times [s] of a swing's samples 1.. after its first (:mod:`planner.motion.time_law`).

        A swing searched in joint space around an edge (``over_edge``) moves its joints at
        ``OVER_EDGE_SPEED_FRACTION`` of their limits.
        """
        from planner.body.robot_scale import time_scale
        from planner.motion.time_law import (
            FOOT_ACCEL_M_S2,
            FOOT_SPEED_M_S,
            JOINT_SPEED_FRACTION,
            LANDING_SPEED_M_S,
            OVER_EDGE_SPEED_FRACTION,
            swing_durations_s,
        )

        if len(path) < 2:
            return np.zeros(0)
        over_edge = any(sample.info.get("over_edge") for sample in path)
        k = time_scale(self.robot)
        dt = swing_durations_s(
            np.array([s.feet_W[leg] for s in path]),
            np.array([s.joints_rad.ravel() for s in path]),
            foot_speed_m_s=FOOT_SPEED_M_S * k,
            landing_speed_m_s=LANDING_SPEED_M_S * k,
            foot_accel_m_s2=FOOT_ACCEL_M_S2,
            least_s=self.settings.swing_time_s,
            vmax_rad_s=self._joint_speed_limits(),
            fraction=OVER_EDGE_SPEED_FRACTION if over_edge else JOINT_SPEED_FRACTION,
        )
        return np.cumsum(dt)

    def step_samples(self, step: Step) -> tuple[list[State], NDArray[np.float64]]:
        """A step's samples and their times [s] from 0 at its start (the executor's too, 8.3).

        The body path, then (a placement) the swing; their shared sample appears once.
        With ``settings.swing_overlap`` the leg lifts before the body move ends where the
        rest of it holds on three legs (:func:`planner.planning.overlap.overlap_step`; found
        once per step, then kept in ``step.overlap``).
        """
        from planner.planning.overlap import overlap_step

        if not step.timed:
            step.overlap = overlap_step(self, step)
            step.timed = True
        if step.overlap is not None:
            return list(step.overlap.states), np.array(step.overlap.times_s)
        states = list(step.body_path)
        times = [0.0] + list(self.body_offsets_s(states))
        if step.ok:
            swing = self.swing_offsets_s(step.swing_path, step.leg)
            states += list(step.swing_path[1:])
            times += list(times[-1] + swing)
        return states, np.array(times[: len(states)])

    def _joint_speed_limits(self) -> NDArray[np.float64] | None:
        """The URDF's velocity limits of the 12 leg joints [rad/s] (None where none is set)."""
        vmax = np.asarray(self.robot.model.velocityLimit, float)[-12:]
        return vmax if len(vmax) == 12 else None

    def _hip_arm_m(self) -> float:
        """Mean horizontal distance of the hips from the base [m] (a turn's lever)."""
        hips = np.array([leg.points_B[0] for leg in self.robot.legs])
        return float(np.mean(np.linalg.norm(hips[:, :2], axis=1)))

    @staticmethod
    def _append(samples: list, times: list, path: list, at_s) -> None:
        """Append a path's samples after the first (equal to the last sample) at times ``at_s``."""
        for s, t in zip(path[1:], at_s, strict=True):
            samples.append(s)
            times.append(float(t))


def _with_leg_joints(state: State, leg: int, joints_rad) -> State:
    """A copy of ``state`` with ``leg``'s joints replaced (the same foot, another branch)."""
    out = state.copy()
    out.joints_rad = state.joints_rad.copy()
    out.joints_rad[leg] = joints_rad
    return out


def _holding_legs(path: list[State], k: int) -> np.ndarray:
    """The legs that carry sample ``k`` of a path: its contacts.

    At a body move's end (four feet down, a three-leg support) the three that will hold it
    when the fourth lifts: balance and torque are judged on them.
    """
    s = path[k]
    sup = np.flatnonzero(s.in_contact)
    if len(sup) == 4 and k == len(path) - 1 and len(s.support) == 3:
        return np.asarray(s.support)
    return sup


def _track_xy(a_W, b_W) -> np.ndarray:
    """(K, 2) points every ``LEVEL_GRID_M`` along a foot's track, ``LEVEL_WIDTH_M`` aside."""
    a, b = np.asarray(a_W, float)[:2], np.asarray(b_W, float).reshape(-1)[:2]
    along = b - a
    n = max(int(np.ceil(np.linalg.norm(along) / LEVEL_GRID_M)), 1)
    side = np.array([-along[1], along[0]]) / max(float(np.linalg.norm(along)), 1e-9)
    offsets = np.arange(-LEVEL_WIDTH_M, LEVEL_WIDTH_M + 1e-9, LEVEL_GRID_M)
    pts = a + np.linspace(0.0, 1.0, n + 1)[:, None, None] * along
    return (pts + offsets[None, :, None] * side).reshape(-1, 2)


def _timed(settings: LocalSettings, robot) -> LocalSettings:
    """``settings`` with unset timing scaled from LittleDog's (:mod:`planner.body.robot_scale`)."""
    from planner.body.robot_scale import time_scale

    k = time_scale(robot)
    if settings.body_speed_m_s is None:
        settings = replace(settings, body_speed_m_s=BODY_SPEED_M_S * k)
    if settings.body_accel_m_s2 is None:
        settings = replace(settings, body_accel_m_s2=BODY_ACCEL_M_S2)
    if settings.swing_time_s is None:
        settings = replace(settings, swing_time_s=SWING_TIME_S * k)
    return settings


__all__ = [
    "LocalPlan",
    "LocalPlanner",
    "LocalSettings",
    "Step",
    "Walk",
]
