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

import math

import numpy as np

from planner.body.kinematics import hip_point_B, kinematics_of
from planner.body.robot import LEG_NAMES
from planner.body.stability import nearest_inside_point_W, polygon_margin_m
from planner.body.state import State
from planner.body.torques import TorqueCheck
from planner.motion.heuristics import nominal_height_m, reference_directions, support_body_target_W
from planner.motion.interpolate import interpolate_leaf
from planner.motion.time_law import BODY_ACCEL_M_S2, BODY_SPEED_M_S, SWING_TIME_S, timed_settings
from planner.motion.trajectory import Trajectory
from planner.planning.body_move import BodyMoves
from planner.planning.driver import (
    ARRIVAL_M,
    GaitDriver,
    LocalPlan,
    NearestWalk,
    PlannedStates,
    Run,
    Walk,
    plan_run,
)
from planner.planning.landing import Landing
from planner.planning.level import LevelGround
from planner.planning.path_checks import TORQUE_FRACTION, PathChecks
from planner.planning.sequence import ContactSequence
from planner.planning.step import Step
from planner.planning.stepping import Stepping
from planner.planning.swing import Swings
from planner.planning.targets import Targets
from planner.planning.timing import Timing
from planner.problems import Theta1, Theta2, Theta3, Theta4
from planner.problems.base import ConstraintCheck
from planner.problems.cache import shared_problem
from planner.problems.options import LocalSettings


class LocalPlanner(
    Targets, LevelGround, PathChecks, Landing, Swings, BodyMoves, ContactSequence, Stepping, Timing
):
    """The shared part of the local planners, for one robot on one terrain.

    Theta problems are built once per support pattern or swing leg and cached; initial
    placement is Theta4 (7.5); :meth:`step` makes one step; subclasses implement
    :meth:`_run`, the loop that chooses steps. The step's parts, one concept per module of
    :mod:`planner.planning`, share the attributes set here: the body target and footholds
    (``targets``), level ground (``level``), the path checks (``path_checks``), the knee
    branch of a landing next to a tall edge (``landing``), the swing (``swing``), the body
    move (``body_move``), the step itself (``stepping``) and its timing (``timing``).
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
        self.settings = timed_settings(settings or LocalSettings(), robot)
        self.kin = kinematics_of(robot)
        self._deadline_s = math.inf  # perf_counter() past which a step tries no more footholds
        self._hips_B = np.array([hip_point_B(lg) for lg in robot.legs])
        self._theta2: dict[tuple[tuple[int, ...], bool], Theta2] = {}
        self._theta3: dict[int, Theta3] = {}
        self._via_theta1: dict[tuple[int, ...], Theta1] = {}
        self._fingerprints: tuple[str, str] | None = None  # robot's, terrain's (shared)
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
            self._theta2[key] = self.shared(Theta2, support=key[0], landing=key[1])
        return self._theta2[key]

    def theta3(self, leg: int) -> Theta3:
        """Theta3 for a swing leg (built on first use)."""
        if leg not in self._theta3:
            self._theta3[leg] = self.shared(Theta3, leg=leg)
        return self._theta3[leg]

    def shared(self, cls, options=None, **kwargs):
        """A Theta problem of this robot, terrain and mu, built once per process.

        ``options`` default to the planner's Theta options (:func:`shared_problem`).
        """
        if self._fingerprints is None:
            self._fingerprints = (self.robot.fingerprint(), self.terrain.fingerprint())
        opts = self.settings.theta if options is None else options
        return shared_problem(
            cls, self.robot, self.terrain, opts, self.mu, self._fingerprints, **kwargs
        )

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
        sol = self.shared(Theta4).solve(p, u_f, u_n)
        self._count("theta4", sol.feasible)
        if not sol.feasible:
            from planner.core.errors import NoSolutionFound

            raise NoSolutionFound(
                f"initial placement at ({x:.3f}, {y:.3f}) failed: {sol.diagnosis}", sol
            )
        return sol.state

    # ---- the run (planner.planning.driver) ----------------------------------------------
    def plan(
        self,
        start_xy,
        goal_xy,
        tau: Trajectory | None = None,
        progress=None,
        start_state: State | None = None,
    ) -> LocalPlan:
        """Plan from ``start_xy`` (or ``start_state``) until the COM is at ``goal_xy``.

        The run is :func:`planner.planning.driver.plan_run`'s, the steps chosen by
        :meth:`_run`. ``progress(distance_m, steps)`` is called after each step. Ctrl-C (or
        SIGTERM under :class:`planner.core.interrupts.Interrupts`) stops planning and
        returns the plan so far (its message says so). Planning runs on one BLAS thread
        (threadpoolctl), whatever was imported first (``planner/__init__.py`` sets it only
        for a numpy not yet loaded): the planner's matrices are small, and BLAS threads
        spinning beside the overlap worker slow it down.
        """
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            return plan_run(self, start_xy, goal_xy, tau, progress, start_state)

    def _run(self, walk: Walk, run: Run) -> str:  # pragma: no cover - abstract
        """Choose and record steps until done (the driver's stop rules); why it stopped."""
        raise NotImplementedError

    def distance_to_goal(self, state: State, run: Run) -> float:
        """Horizontal distance of the whole-body COM to the goal [m]."""
        return float(np.linalg.norm(self.check.com_W(state)[:2] - run.goal))

    def arrival(self, state: State, goal_xy, tau: Trajectory, nearest: bool = False):
        """A body move on all four feet bringing the COM over the goal: (end, path) or None.

        Beyond the paper, whose walk ends after a step: a crawl's keyframes put the COM
        inside a three-foot triangle, and a robot whose stride is long next to
        ``goal_tol_m`` (b1, laikago) stepped in place around the goal without a keyframe
        near it. Tried when the goal lies ``balance_margin_m`` inside the four feet's
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
        if polygon_margin_m(feet, goal_xy) < (0.0 if nearest else self.balance_margin_m):
            return None  # the goal is ahead of the feet: steps, not a body move
        goal = nearest_inside_point_W(feet, goal_xy, self.balance_margin_m)
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

    def stop_reason(self, walk: Walk, run: Run, fails_in_row: int = 0) -> str:
        """Why planning ``walk`` must stop now ("" to go on): the driver's stop rules."""
        run.fails_in_row = fails_in_row
        return GaitDriver(self, run, PlannedStates(walk)).stop_reason()

    def attempts_per_cycle(self) -> int:
        """Step attempts (``run.cycles``) that count as one cycle of the no-progress stop."""
        return 1

    def _log_failure(self, cycle: int, leg: int, phase: str, state: State, why: str) -> None:
        """Log a failed step attempt at ``state`` (the plan's stats keep the last 50)."""
        self.failures.append(
            {
                "cycle": cycle,
                "leg": LEG_NAMES[leg],
                "phase": phase,
                "base_xy": np.round(state.base_position_W[:2], 3).tolist(),
                "why": why,
            }
        )


_Run = Run  # the driver's (planner.planning.driver.Run)

__all__ = [
    "ARRIVAL_M",
    "BODY_ACCEL_M_S2",
    "BODY_SPEED_M_S",
    "SWING_TIME_S",
    "TORQUE_FRACTION",
    "LocalPlan",
    "LocalPlanner",
    "LocalSettings",
    "NearestWalk",
    "Run",
    "Step",
    "Walk",
]
