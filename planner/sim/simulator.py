"""The robot on its terrain in MuJoCo, read and driven in Pinocchio's conventions (section 10).

:class:`Simulator` builds the model of :mod:`planner.sim.model`, places the robot at a
configuration, sets the servos' set-points (with the feed-forward torque that holds a
planned configuration on its planned feet, :func:`planner.body.torques.holding_load`),
steps the physics one control period at a time and reads back the configuration, the
centre of mass, the foot sphere centres and the robot-terrain contacts (:class:`Touches`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from planner.body.torques import TorqueCheck, holding_load
from planner.core.errors import InputError
from planner.sim.model import SimSettings, _effort, _mujoco, build_mjcf, terrain_model

if TYPE_CHECKING:
    from planner.body.robot import Robot
    from planner.planfile.plan import TerrainGrid
    from planner.world.terrain import Terrain

__all__ = ["Simulator", "Touches"]

_Array = NDArray[np.float64]


@dataclass
class Touches:
    """Robot-terrain contacts at one instant."""

    feet: NDArray[np.bool_]  # (4,) foot spheres touching
    body: bool  # the root link (body box) touches
    legs: bool  # a leg link other than a foot touches
    forces: _Array  # (4, 3) force of the terrain on each foot [N], world
    normals: _Array  # (4, 3) contact normal into each touching foot, world


class Simulator:
    """One robot on one terrain in MuJoCo, read and driven in Pinocchio's conventions.

    ``q`` is Pinocchio's free-flyer configuration (xyz, quaternion xyzw, 12 joints);
    set-points and joint arrays are (4, 3) or (12,) in the robot's leg order FL..HR.
    """

    def __init__(
        self,
        robot: Robot,
        grid: TerrainGrid,
        friction: float,
        terrain: Terrain | None = None,
        settings: SimSettings | None = None,
    ):
        mujoco = _mujoco()
        self.mj = mujoco
        self.robot = robot
        self.settings = (settings or SimSettings()).check().for_robot(robot)
        self.terrain = terrain
        self.terrain_model = terrain_model(grid, terrain)
        self.friction = float(friction)
        self.xml = build_mjcf(robot, self.terrain_model, self.friction, self.settings)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        if self.terrain_model.hfield is not None:
            self.model.hfield_data[:] = self.terrain_model.hfield.ravel()
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._jadr = np.array([m.joint(n).qposadr[0] for n in robot.joint_names])
        self._pin_idx = np.array([leg.q_index + k for leg in robot.legs for k in range(3)])
        self.base_body = m.body(m.joint("root").bodyid[0]).id
        terrain_names = {g["name"] for g in self.terrain_model.geoms}
        self.is_terrain = np.array([m.geom(i).name in terrain_names for i in range(m.ngeom)])
        self.foot_geoms = self._find_feet()
        self.body_geoms = np.array(
            [i for i in range(m.ngeom) if m.geom_bodyid[i] == self.base_body], dtype=int
        )
        self.effort = _effort(robot, self.settings)
        self._setpoint = np.zeros(12)
        self._holding: TorqueCheck | None = None
        self.n_sub = max(1, int(round(self.settings.control_dt_s / self.settings.timestep_s)))
        self.history: list[tuple[float, _Array, NDArray[np.bool_]]] = []
        self.history_s = 0.0

    def _find_feet(self) -> NDArray[np.int_]:
        """The sphere geom at each foot frame (compared at Pinocchio's neutral pose)."""
        import pinocchio as pin

        r, m, d = self.robot, self.model, self.data
        q = pin.neutral(r.model)
        q[2] = 1.0
        pdata = r.model.createData()
        pin.framesForwardKinematics(r.model, pdata, q)
        self.set_q(q)
        self.mj.mj_forward(m, d)
        spheres = [
            i
            for i in range(m.ngeom)
            if m.geom_type[i] == self.mj.mjtGeom.mjGEOM_SPHERE and not self.is_terrain[i]
        ]
        out = []
        for f in r.foot_frames:
            p = pdata.oMf[r.model.getFrameId(f)].translation
            dist = [np.linalg.norm(d.geom_xpos[i] - p) for i in spheres]
            if not dist or min(dist) > 2e-3:
                raise InputError(
                    f"{r.urdf_path}: no collision sphere at foot frame '{f}' in MuJoCo's import"
                )
            out.append(spheres[int(np.argmin(dist))])
        return np.array(out, dtype=int)

    # ---- state ----------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return float(self.data.time)

    def set_q(self, q: Any, lift_m: float = 0.0) -> None:
        """Place the robot at Pinocchio configuration ``q`` (raised by ``lift_m``), at rest."""
        q = np.asarray(q, float)
        qpos = self.data.qpos
        qpos[:3] = q[:3] + [0.0, 0.0, lift_m]
        qpos[3:7] = [q[6], q[3], q[4], q[5]]
        qpos[self._jadr] = q[self._pin_idx]
        self.data.qvel[:] = 0.0
        self.set_targets(q[self._pin_idx])
        self.mj.mj_forward(self.model, self.data)

    def q(self) -> _Array:
        """Pinocchio configuration (19,) of the simulated robot."""
        qpos = self.data.qpos
        q = np.zeros(self.robot.model.nq)
        q[:3] = qpos[:3]
        q[3:7] = [qpos[4], qpos[5], qpos[6], qpos[3]]
        q[self._pin_idx] = qpos[self._jadr]
        return q

    def joints(self) -> _Array:
        """(12,) joint angles, robot order."""
        return self.data.qpos[self._jadr].copy()

    def base_rotation(self) -> _Array:
        """(3, 3) base rotation, body to world."""
        return self.data.xmat[self.base_body].reshape(3, 3).copy()

    def com_W(self) -> _Array:
        """Whole-body centre of mass [m], world."""
        return self.data.subtree_com[self.base_body].copy()

    def foot_centres_W(self) -> _Array:
        """(4, 3) foot sphere centres [m], world."""
        return self.data.geom_xpos[self.foot_geoms].copy()

    def set_targets(self, joints: Any, torque_ff_nm: Any = None) -> None:
        """Servo set-points: (12,) or (4, 3) joint angles [rad], robot order.

        ``torque_ff_nm`` (12,): feed-forward torques, applied as the set-point offset
        tau / kp (the servo's torque at the set-point is then tau; it still saturates).
        """
        self._setpoint = np.asarray(joints, float).ravel().copy()
        ctrl = self._setpoint
        if torque_ff_nm is not None:
            ctrl = ctrl + np.asarray(torque_ff_nm, float).ravel() / self.settings.kp_nm_per_rad
        self.data.ctrl[:] = ctrl

    def targets(self) -> _Array:
        """(12,) current joint set-points (without the feed-forward offset)."""
        return self._setpoint.copy()

    def holding_torques_nm(self, q: Any, contact: Any) -> _Array:
        """(N, 12) feed-forward torques for configurations q (N, 19) on contact (N, 4) feet.

        Zeros when ``settings.feedforward`` is off.
        """
        q = np.atleast_2d(np.asarray(q, float))
        if not self.settings.feedforward:
            return np.zeros((len(q), 12))
        if self._holding is None:
            self._holding = TorqueCheck(self.robot)
        c = np.atleast_2d(np.asarray(contact, bool))
        return holding_load(self._holding, q, c, self.friction, self.terrain)[1]

    def saturated(self) -> bool:
        """Whether any servo is at its torque limit."""
        return bool(np.any(np.abs(self.data.actuator_force) >= self.effort - 1e-9))

    def touches(self) -> Touches:
        """Contacts of the robot with the terrain now (forces and normals world frame)."""
        d = self.data
        out = Touches(np.zeros(4, bool), False, False, np.zeros((4, 3)), np.zeros((4, 3)))
        f6 = np.zeros(6)
        for k in range(d.ncon):
            c = d.contact[k]
            g1, g2 = int(c.geom1), int(c.geom2)
            if self.is_terrain[g1] == self.is_terrain[g2]:
                continue
            robot_geom, sign = (g2, 1.0) if self.is_terrain[g1] else (g1, -1.0)
            hit = np.flatnonzero(self.foot_geoms == robot_geom)
            if hit.size:
                i = int(hit[0])
                out.feet[i] = True
                frame = np.asarray(c.frame).reshape(3, 3)
                self.mj.mj_contactForce(self.model, d, k, f6)
                out.forces[i] += sign * (frame.T @ f6[:3])
                out.normals[i] = sign * frame[0]
            elif robot_geom in self.body_geoms:
                out.body = True
            else:
                out.legs = True
        return out

    def contact_point_velocity(self, leg: int, normal_W: _Array) -> _Array:
        """World velocity of the foot sphere's material point touching along ``normal_W``.

        Zero for a foot that rolls without sliding; the sliding velocity otherwise.
        """
        v6 = np.zeros(6)
        self.mj.mj_objectVelocity(
            self.model, self.data, self.mj.mjtObj.mjOBJ_GEOM, int(self.foot_geoms[leg]), v6, 0
        )
        r = -self.robot.foot_radius_m * np.asarray(normal_W, float)
        w = v6[:3]  # w x r, written out (np.cross costs more than the physics step)
        return v6[3:] + np.array(
            [w[1] * r[2] - w[2] * r[1], w[2] * r[0] - w[0] * r[2], w[0] * r[1] - w[1] * r[0]]
        )

    # ---- stepping -------------------------------------------------------------------------
    def tick(self) -> None:
        """Advance one control period (``n_sub`` physics steps); keep history if asked."""
        self.mj.mj_step(self.model, self.data, nstep=self.n_sub)
        if self.history_s > 0.0:
            self.history.append((self.time, self.q(), self.touches().feet))
            while self.history and self.history[0][0] < self.time - self.history_s - 0.1:
                self.history.pop(0)

    def settle(self, q0: Any, duration_s: float) -> None:
        """Start at ``q0`` (2 mm up) holding its joints, and let the robot settle."""
        self.set_q(q0, lift_m=0.002)
        q0 = np.asarray(q0, float)
        self.set_targets(q0[self._pin_idx], self.holding_torques_nm(q0, np.ones(4, bool))[0])
        end = self.time + duration_s
        while self.time < end - 1e-9:
            self.tick()
