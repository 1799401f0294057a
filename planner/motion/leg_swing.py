"""Swing paths in the swing leg's joint space, around edges (beyond the paper's eq. 6a).

:func:`planner.motion.interpolate.swing_path` plans the *foot*: it lifts the sphere over the
highest terrain under its track. Over a barrier or onto a high step that is not enough:
the shank trailing the foot (or the knee, when the landing pose has the knee on the other
side of the hip-foot line) cuts through the edge although both end poses are clear. Here
the body and the three stance feet stay where Theta3 left them and the swing leg's three
joints find their own way:

1. a grid over the leg's joint box (hip roll at ``ROLL_LEVELS`` values over its range and
   at its lift and touch-down angles, hip pitch at ``GRID`` values from ``PITCH_SPAN_RAD``
   behind to ``PITCH_SPAN_RAD`` beyond its two end angles, the knee at ``GRID`` values
   over its range; within the URDF limits): a thigh over an edge may have to swing
   sideways to pass it;
2. a configuration is *free* when the leg's thigh and shank capsules
   (:mod:`planner.body.links`) are ``LINK_MARGIN_M`` above the sharp terrain (under a disc of
   their radius) and the foot sphere ``FOOT_MARGIN_M`` above it;
3. a shortest path in joint space (Dijkstra on the grid's 26-neighbour graph, scipy's
   ``csgraph``) from the lift-off pose to the touch-down pose, each entered from a
   *pre-pose* a few millimetres up the terrain normal (IK on the same knee branch), then
   shortcut (a waypoint is dropped where the straight joint segment stays free), and
   every segment of the result checked every ``SEGMENT_STEP_RAD`` / s (s: the robot's
   length scale, :mod:`planner.body.robot_scale`: the foot moves as far between checks);
4. ``n`` samples along it by joint-space arc length with a smootherstep in time (the foot
   starts and stops at rest), which is how the executor's servos interpolate anyway.

The caller checks the samples like any path (reach, leg links exactly, balance, torques).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from planner.body.contact import E_Z, foot_centre_from_contact
from planner.body.kinematics import kinematics_of
from planner.body.links import disc_clearance, leg_links
from planner.body.robot_scale import length_scale
from planner.body.state import State
from planner.motion.interpolate import smootherstep

__all__ = ["joint_space_swing", "can_lift"]

_Array = NDArray[np.float64]
GRID = 20  # values of hip pitch and knee on the grid
PITCH_SPAN_RAD = 1.0  # hip pitch beyond its lift and touch-down angles searched
ROLL_LEVELS = 3  # values of hip roll over its range (plus its lift and touch-down angles)
LINK_MARGIN_M = 0.002  # a free configuration keeps thigh and shank this far above the terrain
FOOT_MARGIN_M = 0.005  # ... and the foot sphere this far
LIFT_M = 0.01  # pre-poses: the sphere centre this far up the terrain normal
PRE_LIFTS_M = (LIFT_M, 0.0075, 0.006)  # ... or less, where the knee's limit is near
LAZY_ROUNDS = 20  # shortest paths tried while their edges turn out blocked
SEGMENT_STEP_RAD = 0.03  # straight joint segments are checked every this much


class _Free:
    """Free-space test of one leg's configurations at a fixed body pose (batched)."""

    def __init__(self, robot, terrain, state: State, leg: int):
        self.robot, self.terrain, self.leg = robot, terrain, leg
        self.links = leg_links(robot)
        self.segment_step_rad = SEGMENT_STEP_RAD / length_scale(robot)
        self.kin = kinematics_of(robot)
        self.caps = [c for c, cap in enumerate(self.links.capsules) if cap.leg == leg]
        self.state = state
        self.R, self.p = state.base_rotation_W, state.base_position_W
        self.rho = float(robot.foot_radius_m)

    def __call__(self, joints: _Array) -> _Array:
        """(k,) True where the leg at ``joints`` (k, 3) is clear of the terrain."""
        import pinocchio as pin

        links, model, data = self.links, self.links.model, self.links.data
        j = self.state.joints_rad.copy()
        pts, rad, own = [], [], []
        for k, th in enumerate(joints):
            j[self.leg] = th
            q = self.robot.q_from(self.p, self.state.base_quaternion_xyzw, j)
            pin.forwardKinematics(model, data, q)
            for c in self.caps:
                M = data.oMi[links.capsules[c].joint_id]
                pts.append(links.points_J[c] @ np.asarray(M.rotation).T + np.asarray(M.translation))
                rad.append(np.full(len(links.points_J[c]), links.capsules[c].radius_m))
                own.append(np.full(len(links.points_J[c]), k))
        pts, rad, own = np.concatenate(pts), np.concatenate(rad), np.concatenate(own)
        gap = np.full(len(joints), np.inf)
        np.minimum.at(gap, own, disc_clearance(self.terrain, pts, rad))
        foot = disc_clearance(self.terrain, self.centres_W(joints), self.rho)
        return (gap >= LINK_MARGIN_M) & (foot >= FOOT_MARGIN_M)

    def centres_W(self, joints: _Array) -> _Array:
        """(k, 3) foot sphere centres [m], world frame."""
        feet_B = np.array([self.kin.foot_B(self.leg, th) for th in joints])
        return feet_B @ self.R.T + self.p

    def segment_free(self, a: _Array, b: _Array) -> bool:
        """Whether the straight joint segment a-b is free (checked every SEGMENT_STEP_RAD / s)."""
        m = max(2, int(np.ceil(np.abs(b - a).max() / self.segment_step_rad)) + 1)
        u = np.linspace(0.0, 1.0, m)[:, None]
        return bool(np.all(self(a + u * (b - a))))


def _pre_pose(free: _Free, state: State, leg: int) -> _Array | None:
    """Joints with the sphere LIFT_M up the terrain normal from its contact (same knee).

    Where the knee's branch does not reach that far (a knee near its limit: LittleDog's
    hind knees bend rearward to -1 rad only) the lower ``PRE_LIFTS_M``, each clear of
    ``FOOT_MARGIN_M``; None when none is reachable on the branch and free. Taking the
    other branch there (as IK offers) made the last straight joint segment flip the knee
    with the foot 2 cm into the ground.
    """
    kin = free.kin
    c = foot_centre_from_contact(free.terrain, state.feet_W[leg], free.rho)
    n = np.asarray(free.terrain.normal(state.feet_W[leg]), float).reshape(3)
    th = state.joints_rad[leg]
    knee = kin.knee_direction(leg, th)
    for lift in PRE_LIFTS_M:
        up = c + lift * n
        ik = kin.ik_leg(leg, free.R.T @ (up - free.p), reference_rad=th, knee=knee)
        if ik.reachable and not ik.knee_flipped and free(ik.joints_rad[None])[0]:
            return ik.joints_rad
    return None


def can_lift(robot, terrain, state: State, leg: int) -> bool:
    """Whether ``leg`` has a free pre-pose over its contact in ``state`` (:func:`_pre_pose`).

    The first and last poses of every joint-space swing: a leg that cannot lift its foot
    a few millimetres up the terrain normal with its links clear (a knee forward against
    a riser) has no swing from there, nor one that lands there.
    """
    return _pre_pose(_Free(robot, terrain, state, leg), state, leg) is not None


def _shortcut(free: _Free, way: list[_Array]) -> list[_Array]:
    """Drop waypoints whose neighbours see each other through free space (greedy)."""
    out = [way[0]]
    i = 0
    while i < len(way) - 1:
        j = len(way) - 1
        while j > i + 1 and not free.segment_free(way[i], way[j]):
            j -= 1
        out.append(way[j])
        i = j
    return out


def joint_space_swing(
    robot, terrain, state_lift: State, state_touch: State, n: int, leg: int
) -> list[State] | None:
    """Samples of a swing of ``leg`` found in its joint space, or None (see module doc).

    ``state_lift`` and ``state_touch`` must share the body pose and the three stance feet
    (a swing after Theta3). The ends are those two states; interior samples are on
    S_{leg+1} with the swing foot stored as its sphere's lowest point.
    """
    i = int(leg)
    if not (
        np.allclose(state_lift.base_position_W, state_touch.base_position_W, atol=1e-9)
        and np.allclose(state_lift.base_rotation_W, state_touch.base_rotation_W, atol=1e-9)
    ):
        return None
    free = _Free(robot, terrain, state_lift, i)
    a, b = state_lift.joints_rad[i].copy(), state_touch.joints_rad[i].copy()
    a_up, b_up = _pre_pose(free, state_lift, i), _pre_pose(free, state_touch, i)
    if a_up is None or b_up is None:
        return None
    lo, hi = robot.lower_rad[i], robot.upper_rad[i]
    rolls = np.unique(np.concatenate([[a_up[0], b_up[0]], np.linspace(lo[0], hi[0], ROLL_LEVELS)]))
    span = [min(a_up[1], b_up[1]) - PITCH_SPAN_RAD, max(a_up[1], b_up[1]) + PITCH_SPAN_RAD]
    pitch = np.linspace(max(lo[1], span[0]), min(hi[1], span[1]), GRID)
    knee = np.linspace(lo[2], hi[2], GRID)
    R0, P, K = np.meshgrid(np.arange(len(rolls)), np.arange(GRID), np.arange(GRID), indexing="ij")
    idx = np.column_stack([R0.ravel(), P.ravel(), K.ravel()])
    nodes = np.column_stack([rolls[idx[:, 0]], pitch[idx[:, 1]], knee[idx[:, 2]]])
    ok = free(nodes)
    # the graph: free grid nodes, their free neighbours, and the two pre-poses
    shape = (len(rolls), GRID, GRID)
    flat = np.ravel_multi_index(idx.T, shape)
    rows, cols, w = [], [], []
    for d in np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).reshape(3, -1).T:
        if not d.any():
            continue
        nb = idx + d
        inside = np.all((nb >= 0) & (nb < np.array(shape)), axis=1)
        src = flat[inside]
        dst = np.ravel_multi_index(nb[inside].T, shape)
        keep = ok[src] & ok[dst]
        rows.append(src[keep])
        cols.append(dst[keep])
        w.append(np.linalg.norm(nodes[src[keep]] - nodes[dst[keep]], axis=1))
    N = len(nodes)
    start, goal = N, N + 1
    for k, end in ((start, a_up), (goal, b_up)):
        d = np.linalg.norm(nodes - end, axis=1)
        near = [int(j) for j in np.argsort(d)[:8] if ok[j] and free.segment_free(end, nodes[j])]
        rows.append(np.full(len(near), k))
        cols.append(np.array(near, dtype=int))
        w.append(d[near])
    if free.segment_free(a_up, b_up):
        rows.append(np.array([start]))
        cols.append(np.array([goal]))
        w.append(np.array([np.linalg.norm(a_up - b_up)]))
    rows, cols, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(w)
    allnodes = np.vstack([nodes, a_up, b_up])
    for _ in range(LAZY_ROUNDS):  # lazy PRM: check the edges of a shortest path only
        g = coo_matrix((w, (rows, cols)), (N + 2,) * 2).tocsr()
        dist, pred = dijkstra(g, directed=False, indices=start, return_predecessors=True)
        if not np.isfinite(dist[goal]):
            return None
        chain, k = [goal], goal
        while k != start:
            k = int(pred[k])
            chain.append(k)
        chain.reverse()
        bad = [
            (u, v)
            for u, v in zip(chain[:-1], chain[1:], strict=True)
            if not free.segment_free(allnodes[u], allnodes[v])
        ]
        if not bad:
            break
        drop = np.zeros(len(rows), bool)
        for u, v in bad:  # neighbouring free nodes whose edge cuts a corner
            drop |= ((rows == u) & (cols == v)) | ((rows == v) & (cols == u))
        rows, cols, w = rows[~drop], cols[~drop], w[~drop]
    else:
        return None
    way = _shortcut(free, [allnodes[k] for k in chain])
    way = [a, *way, b]
    return _sample(free, state_lift, state_touch, np.array(way), n)


def _sample(free: _Free, lift: State, touch: State, way: _Array, n: int):
    """States along the joint polyline ``way`` (arc length, smootherstep in time).

    ``n`` samples evenly spaced in time, and one at each interior vertex of ``way``: the
    executor moves the joints linearly between samples, so two samples on either side of
    a vertex would cut its corner, through configurations the segment checks never saw
    (a knee flipping between two such samples can sweep the foot through the ground).
    With the vertices, every interval lies on one checked segment.
    """
    seg = np.linalg.norm(np.diff(way, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.linspace(0.0, 1.0, int(n))
    u = smootherstep(s) * cum[-1]
    if cum[-1] > 0.0 and len(way) > 2:
        s_table = np.linspace(0.0, 1.0, 4001)  # smootherstep is increasing: invert by table
        at = cum[1:-1]
        s = np.concatenate([s, np.interp(at / cum[-1], smootherstep(s_table), s_table)])
        u = np.concatenate([u, at])
        order = np.argsort(u, kind="stable")
        s, u = s[order], u[order]
        keep = np.concatenate([[True], np.diff(u) > 1e-9 * max(cum[-1], 1.0)])
        keep[-1] = True
        s, u = s[keep], u[keep]
    n = len(s)
    joints_i = np.column_stack([np.interp(u, cum, way[:, k]) for k in range(3)])
    centres = free.centres_W(joints_i)
    i = free.leg
    out = []
    for k in range(int(n)):
        if k in (0, n - 1):
            end = (lift if k == 0 else touch).copy()
            end.info.update(nu=float(s[k]), ik_ok=True, ik_error_m=0.0, unreachable_legs=[])
            out.append(end)
            continue
        joints = lift.joints_rad.copy()
        joints[i] = joints_i[k]
        feet = lift.feet_W.copy()
        feet[i] = centres[k] - free.rho * E_Z
        out.append(
            State(
                base_position_W=lift.base_position_W.copy(),
                base_rotation_W=lift.base_rotation_W.copy(),
                feet_W=feet,
                joints_rad=joints,
                stratum=i + 1,
                support=tuple(j for j in range(4) if j != i),
                info=dict(nu=float(s[k]), ik_ok=True, ik_error_m=0.0, unreachable_legs=[]),
            )
        )
    return out
