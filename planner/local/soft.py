"""Local planning by soft persuasion with a gait step queue (paper section 8.2).

One cycle moves one leg, as in figure 6 of the paper:

1. take the next leg i_f from the gait queue;
2. move the body on the current leaf of S0 so that the three other feet carry the weight:
   Theta2 with the target r_c* = Lambda_c(Psi, i_f) (sections 7.3, 8.2.1), the path
   interpolated along the leaf (eq. 6b);
3. lift leg i_f (S0 -> S_if) and place it with Theta3 at a foothold near
   Lambda_t(Psi, i_f, tau) (sections 7.4, 8.2.2); the swing follows a path that clears the
   terrain (beyond eq. 6a, :func:`planner.interpolate.swing_path`); back on S0;
4. push i_f to the back of the queue. On a failure of Theta2 or Theta3 the leg is swapped
   with the next one and retried after it (comment ii of 8.2); a failed foothold is
   retried with a shorter stride.

Planning stops when the centre of mass is within ``goal_tol_m`` of the goal, the step or
time budget runs out, or every leg has failed in a row. Whatever was planned is kept.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from planner.heuristics import lambda_c, lambda_t, nominal_height_m, reference_directions
from planner.interpolate import interpolate_leaf, interpolate_swing
from planner.kinematics import kinematics_of
from planner.local.gait_queue import CRAWL, GaitQueue
from planner.problems import Theta2, Theta3, Theta4, ThetaOptions
from planner.problems.base import ConstraintCheck
from planner.robot import LEG_NAMES
from planner.state import State
from planner.trajectory import Trajectory


@dataclass
class LocalSettings:
    """What the local planner trades off.

    step_m : stride of Lambda_t; default 0.35 x leg reach (6.3 cm for LittleDog).
    shrink : Lambda_c's pull from the support centroid toward its incentre (stability
        margin before a leg lifts); 0 is the paper.
    body_speed_m_s, swing_time_s : timing of the samples (quasi-static: slow).
    goal_tol_m : distance of the COM (xy) to the goal that counts as arrived.
    """

    gait: tuple[int, ...] = CRAWL
    step_m: float | None = None
    shrink: float = 0.3
    clearance_m: float | None = None
    body_samples: int = 8
    swing_samples: int = 12
    body_speed_m_s: float = 0.04
    swing_time_s: float = 0.6
    goal_tol_m: float = 0.05
    max_cycles: int = 400
    time_budget_s: float = 120.0
    min_step_fraction: float = 0.25
    theta: ThetaOptions = field(default_factory=ThetaOptions)


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


class SoftPlanner:
    """The gait-queue driver of section 8.2 for one robot on one terrain."""

    def __init__(self, robot, terrain, mu: float | None = None, settings=None):
        self.robot = robot
        self.terrain = terrain
        self.mu = float(terrain.spec.get("friction", 0.7) if mu is None else mu)
        self.settings = settings or LocalSettings()
        self.kin = kinematics_of(robot)
        self._theta2: dict[tuple[int, ...], Theta2] = {}
        self._theta3: dict[int, Theta3] = {}
        self.stats = {"theta2": [0, 0], "theta3": [0, 0], "theta4": [0, 0], "swing_ik": [0, 0]}

    # ---- problems, built once per support pattern / leg --------------------------------
    def theta2(self, support) -> Theta2:
        """Theta2 for a support pattern (built on first use)."""
        key = tuple(sorted(support))
        if key not in self._theta2:
            self._theta2[key] = Theta2(
                self.robot, self.terrain, support=key, options=self.settings.theta, mu=self.mu
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
        self.stats[key][0] += 1
        self.stats[key][1] += int(ok)

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
            from planner.errors import NoSolutionFound

            raise NoSolutionFound(
                f"initial placement at ({x:.3f}, {y:.3f}) failed: {sol.diagnosis}", sol
            )
        return sol.state

    # ---- one cycle ---------------------------------------------------------------------
    def body_move(self, state: State, leg: int, tau: Trajectory):
        """Theta2 onto the three legs other than ``leg``; returns (solution, samples)."""
        support = tuple(i for i in range(4) if i != leg)
        d_c = self.com_height_m()
        rc = lambda_c(self.robot, self.terrain, state, leg, d_c_m=d_c, shrink=self.settings.shrink)
        u_f, u_n = reference_directions(tau, self.terrain, rc)
        sol = self.theta2(support).solve(state, rc, u_f, u_n)
        self._count("theta2", sol.feasible)
        if not sol.feasible:
            return sol, []
        sol.state.support = support
        path = interpolate_leaf(
            self.robot, self.terrain, state, sol.state, self.settings.body_samples
        )
        return sol, path

    def swing(self, state: State, leg: int, tau: Trajectory, step_m: float):
        """Theta3 for ``leg`` toward Lambda_t; returns (solution, samples)."""
        target = lambda_t(self.robot, self.terrain, state, leg, tau, step_m=step_m)
        lifted = state.copy()
        lifted.stratum = leg + 1
        sol = self.theta3(leg).solve(lifted, target)
        self._count("theta3", sol.feasible)
        if not sol.feasible:
            return sol, []
        touch = sol.state
        touch.support = tuple(range(4))
        path = interpolate_swing(
            self.robot,
            self.terrain,
            lifted,
            touch,
            self.settings.swing_samples,
            self.settings.clearance_m,
            swing_leg=leg,
        )
        ok = all(s.info.get("ik_ok", True) for s in path)
        self._count("swing_ik", ok)
        if not ok:
            sol.feasible = False
            sol.diagnosis = f"swing of {LEG_NAMES[leg]}: the swing path leaves the leg's reach"
            return sol, []
        return sol, path

    # ---- the loop ----------------------------------------------------------------------
    def plan(
        self,
        start_xy,
        goal_xy,
        tau: Trajectory | None = None,
        progress=None,
        start_state: State | None = None,
    ) -> LocalPlan:
        """Plan from ``start_xy`` (or ``start_state``) until the COM is at ``goal_xy``."""
        st = self.settings
        t_begin = time.perf_counter()
        if tau is None:
            tau = Trajectory.straight(start_xy, goal_xy, self.terrain, self.com_height_m())
        state = start_state if start_state is not None else self.initial_state(start_xy, tau)
        goal = np.asarray(goal_xy, float)[:2]
        step0 = st.step_m if st.step_m is not None else 0.35 * float(np.min(self.robot.reach_m))
        queue = GaitQueue(st.gait)
        keyframes = [state]
        samples, times = [state], [0.0]
        fails_in_row, cycles, steps = 0, 0, 0
        last_failure = ""
        step_scale = {i: 1.0 for i in range(4)}
        message = ""
        check = ConstraintCheck(self.robot, self.terrain, st.theta)

        def com_xy(s):
            return check.com_W(s)[:2]

        while True:
            dist = float(np.linalg.norm(com_xy(state) - goal))
            if dist <= st.goal_tol_m:
                message = f"reached the goal: COM {dist * 100:.1f} cm from it"
                break
            if cycles >= st.max_cycles:
                message = f"stopped after {cycles} cycles (max_cycles)"
                break
            if time.perf_counter() - t_begin > st.time_budget_s:
                message = f"stopped by the time budget ({st.time_budget_s:.0f} s)"
                break
            if fails_in_row >= 8:
                message = f"stuck: 8 failed step attempts in a row; last: {last_failure}"
                break
            cycles += 1
            leg = queue.pop()
            sol2, body_path = self.body_move(state, leg, tau)
            if not sol2.feasible:
                last_failure = f"{LEG_NAMES[leg]} body move: {sol2.diagnosis}"
                queue.swap(leg)
                fails_in_row += 1
                continue
            moved = sol2.state
            sol3, swing_path = self.swing(moved, leg, tau, step0 * step_scale[leg])
            if not sol3.feasible:
                last_failure = f"{LEG_NAMES[leg]} foot placement: {sol3.diagnosis}"
                step_scale[leg] = max(step_scale[leg] * 0.5, st.min_step_fraction)
                # keep the body move: the robot stands on three legs safely there
                self._append(samples, times, body_path, self._body_time(state, moved))
                keyframes.append(moved)
                state = moved
                queue.swap(leg)
                fails_in_row += 1
                continue
            step_scale[leg] = 1.0
            fails_in_row = 0
            steps += 1
            self._append(samples, times, body_path, self._body_time(state, moved))
            self._append(samples, times, swing_path, st.swing_time_s)
            keyframes += [moved, self._swing_keyframe(swing_path, leg, check), sol3.state]
            state = sol3.state
            queue.push(leg)
            if progress is not None:
                progress(dist, steps)
        dist = float(np.linalg.norm(com_xy(state) - goal))
        stats = {
            "cycles": cycles,
            "steps": steps,
            "planning_time_s": time.perf_counter() - t_begin,
            "solves": {k: {"count": v[0], "feasible": v[1]} for k, v in self.stats.items()},
        }
        return LocalPlan(
            keyframes=keyframes,
            samples=samples,
            times=times,
            reached_goal=dist <= st.goal_tol_m,
            distance_to_goal_m=dist,
            message=message,
            stats=stats,
        )

    def _swing_keyframe(self, path: list[State], leg: int, check) -> State:
        """The mid-swing configuration on S_leg, with its eq. 5 forces (3 stance feet)."""
        from planner.statics import equilibrating_forces

        mid = path[len(path) // 2].copy()
        mid.stratum = leg + 1
        mid.support = tuple(i for i in range(4) if i != leg)
        eq = equilibrating_forces(
            mid.feet_W, check.com_W(mid), self.robot.total_mass_kg, mid.support
        )
        mid.forces_W = None if eq.degenerate else eq.forces
        return mid

    def _body_time(self, a: State, b: State) -> float:
        d = float(np.linalg.norm(b.base_position_W - a.base_position_W))
        return max(d / self.settings.body_speed_m_s, 0.2)

    @staticmethod
    def _append(samples: list, times: list, path: list, duration_s: float) -> None:
        """Append a path's samples after the first (equal to the last sample) with times."""
        if len(path) < 2:
            return
        t0 = times[-1]
        k = len(path) - 1
        for j, s in enumerate(path[1:], start=1):
            samples.append(s)
            times.append(t0 + duration_s * j / k)


__all__ = ["LocalPlan", "LocalSettings", "SoftPlanner"]
