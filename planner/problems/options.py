"""The tunables of the local planners (section 8) and of the Theta problems (section 7).

:class:`LocalSettings` and :class:`ThetaOptions` are plain data with no heavy import, so the
command line (:mod:`planner.planning.settings`) can list and check them without loading CasADi or
Pinocchio. Their defaults that other modules share (the margins chosen from MuJoCo runs)
live in :mod:`planner.body.margins`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from planner.body.margins import (
    BALANCE_MARGIN_M,
    COMMANDED_TORQUE_FRACTION,
    SWAY_STIFFNESS_AIM_MG_PER_L,
    SWAY_STIFFNESS_MIN_MG_PER_L,
)
from planner.motion.gait_queue import CRAWL

__all__ = ["LocalSettings", "ThetaOptions"]


@dataclass
class ThetaOptions:
    """Settings shared by the Theta problems; what each trades off.

    weights : gamma_1..gamma_5 of Theta1, Theta2, Theta4 (section 7.3). gamma_1, gamma_2
        are large because log sigma_1 = log cos(angle) is flat: with 50, a 10 degree tilt
        or yaw costs about as much as a 0.9 cm COM miss (gamma_4 = 2, com_length 1 cm);
        with the paper's equal weights the COM term alone decided the posture and the
        body rolled and yawed by 15 degrees to shift its COM. Raise gamma_4 to
        follow the COM target more tightly; raise gamma_3 for stances nearer theta_nor.
    clearance_m : delta_c, the least height of every vertex of the body box P above the
        terrain (constraint b). Lower it when a step or barrier needs the belly closer.
    forces : impose inequalities (d), (e) on the eq. 5 forces (the paper's default).
    min_normal_force_frac : (d) asks F_i.n_i >= this fraction of m g (strictly positive).
    balance_margin_m : on three legs, the COM at least this far (horizontally) inside every
        edge of the support triangle (:mod:`planner.body.stability`: chosen from MuJoCo falls).
    sigma_floor : lower bound of sigma1, sigma2, sigma5 (orientation stays forward and up).
    torque_fraction : on three legs, Theta2's pose needs no support joint beyond this
        fraction of its URDF effort in the force distribution the servos are commanded
        (effort-weighted least squares inside the cones, :mod:`planner.body.torques`); the
        planner's paths allow the same (``COMMANDED_TORQUE_FRACTION``). A pose beyond it is
        solved again with the torque rows (:func:`planner.body.torques.least_squares_ratios_ca`).
        None: off. Without it Theta2 chose three-leg stances whose hind knee needed 93-140 %
        of its 0.6 N m on an 18 degree incline and an 8 cm step down, and the swing from
        there failed. It is the paths' fraction: a pose allowed less than its paths lost
        the 10 cm climb of ``tests/test_climb.py`` (the recursive planner ran out of time).
    sway_stiffness : on three legs, Theta2's pose has at least this sway stiffness on the
        robot's servos, in units of m g / L (:mod:`planner.body.stiffness`; the feed-forward:
        the commanded torques); a pose below it is solved again with the stiffness as
        rows. None: off. Without it plans fell in MuJoCo open loop from their softest
        three-leg stances (44-83 N/m).
    sway_stiffness_aim : ... and a feasible pose below this is solved again with rows that
        ask it, kept where they find one (None: not tried).
    max_tilt_rad : Theta2's body z axis at most this far from u_n (sigma2 >= its cosine);
        None: only ``sigma_floor``. The objective alone lets the body roll 17-29 degrees
        where the constraints press (edges, a stretched leg), but a 20 degree bound made
        Theta2 pick other poses that walked worse in MuJoCo (an 8 cm step down ended 15 cm
        from its planned end open loop, 3 cm without): off by default.
    whole_body_com : whole-body centre of mass (default) or the body link's (the paper).
    max_iter, tol : IPOPT's iteration cap and tolerance. If a problem fails with
        "Maximum_Iterations_Exceeded", raise max_iter or start nearer (warm start).
        Feasibility does not rest on tol: constraints are held to 1e-9 by IPOPT and
        checked independently to FEASIBILITY_TOL.
    mu_init : IPOPT's first barrier parameter with the monotone strategy. The problems
        are warm-started next to their optimum; IPOPT's default (adaptive, 0.1) pushed
        the start off it and took 25 iterations, sometimes to another IK branch.
    """

    weights: tuple[float, float, float, float, float] = (50.0, 50.0, 1.0, 2.0, 0.5)
    placement_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)  # Theta3 gamma_1..3
    clearance_m: float = 0.02
    forces: bool = True
    min_normal_force_frac: float = 0.02
    balance_margin_m: float = BALANCE_MARGIN_M
    sigma_floor: float = 0.05
    max_tilt_rad: float | None = None
    torque_fraction: float | None = COMMANDED_TORQUE_FRACTION
    sway_stiffness: float | None = SWAY_STIFFNESS_MIN_MG_PER_L
    sway_stiffness_aim: float | None = SWAY_STIFFNESS_AIM_MG_PER_L
    whole_body_com: bool = True
    friction_eps_N: float = 1e-3
    max_iter: int = 150
    tol: float = 1e-6
    slope_limit: bool = True
    com_length_m: float = 0.01  # sigma4 = exp(-|r_c - r_c*|^2 / (2 com_length_m^2))
    target_length_m: float = 0.01  # Theta3 sigma1 = exp(-|r - r_t|^2 / (2 target_length_m^2))
    joint_scale_rad: float = 1.0  # sigma3 = exp(-|theta - theta_nor|^2 / (2 joint_scale^2))
    jit: bool = False  # NLP functions compiled to C, cached on disk (planner.problems.compiled)
    rolling_feet: bool = False  # Theta2 solves for the centres its stance spheres roll to (4.3)
    lift_ready: bool = False  # landing-ready Theta2 also proves the swing leg can lift off
    mu_init: float | None = 1e-3  # None: IPOPT's adaptive strategy from 0.1


@dataclass
class LocalSettings:
    """What the local planner trades off.

    step_m : stride of Lambda_t; default 0.35 x leg reach (6.3 cm for LittleDog).
    shrink : Lambda_c's pull from the support centroid toward its incentre (stability
        margin before a leg lifts); 0 is the paper.
    body_speed_m_s, body_accel_m_s2, swing_time_s : the time law of the samples
        (:mod:`planner.motion.time_law`): the base's peak speed and acceleration in body moves,
        the least duration of a swing. None: LittleDog's ``BODY_SPEED_M_S``,
        ``BODY_ACCEL_M_S2``, ``SWING_TIME_S``, scaled to the robot by dynamic similarity
        (speeds and times x sqrt(s), accelerations alike, :mod:`planner.body.robot_scale`).
    swing_overlap : the largest share of a body move's duration that the next swing may
        overlap (:mod:`planner.planning.overlap`: the leg lifts once the rest of the move
        holds on three legs); 0: the body rests during every swing (the paper's step).
    goal_tol_m : distance of the COM (xy) to the goal that counts as arrived.
    balance_margin_frac : least friction-cone margin (x m g) at every sample of a path.
    max_fails_in_row : failed step attempts in a row after which the planner is stuck.
    no_progress_cycles : cycles without the COM coming ``PROGRESS_M`` nearer the goal after
        which the planner is stuck (steps in place before an obstacle, some failing).
    follow_support : the body's height and tilt follow the plane of the footholds it will
        stand on; False: the paper's, over the terrain under the body.
    com_target : where the body moves before a swing: "centroid", Lambda_c's (eq. 12, the
        paper's, four body moves per crawl cycle) or "two_beat"
        (:func:`planner.motion.heuristics.two_beat_xy_W`: into both the swing's and the next
        swing's support, two body moves per cycle) where the ground under the feet is level
        (:meth:`LocalPlanner.level_under`), Lambda_c's elsewhere.
    level_stride : the stride of Lambda_t where the ground a swing crosses is level
        (:meth:`LocalPlanner.stride_at`), as a fraction of the shortest leg reach; used
        where longer than ``step_m``. None: ``step_m`` everywhere.
    level_body_accel_m_s2, level_clearance_m, level_body_samples, level_swing_samples :
        the body moves' acceleration bound and samples where the ground under the feet is
        level, the swing height and samples where the ground under the swing's track is
        (None: ``body_accel_m_s2``, ``clearance_m``, ``body_samples``, ``swing_samples``). The
        fast preset walks fast on level ground and as carefully as the defaults elsewhere:
        its settings applied everywhere planned fewer of the named and hard courses and a
        plan fell with feedback (bench/notes/2026-11-26-physics-fast-everywhere.md).
    body_samples, swing_samples : samples of a body move's leaf and of a swing path. The
        time law is exact at the samples only (each interval at constant acceleration):
        long moves and swings run faster, and overlap more, with more of them.
    overlap_worker : search each step's swing overlap in a forked second process while the
        next step is planned (:mod:`planner.planning.prefetch`); the plan is the same to the
        bit either way, only the wall time differs.
    footholds : "search": each step's first foothold from the contact-sequence search
        (:mod:`planner.motion.contact_search`: a gait cycle ahead, certified), Lambda_t's
        where it finds none; "lambda_t": Lambda_t's (eq. 13, section 8.2.2) only.
    restarts : a walk that stalls with time left is planned again, at most this many
        times, with another model of the stance (:mod:`planner.planning.restarts`).
    """

    gait: tuple[int, ...] = CRAWL
    step_m: float | None = None
    shrink: float = 0.3
    clearance_m: float | None = None
    body_samples: int = 8
    swing_samples: int = 12
    body_speed_m_s: float | None = None
    body_accel_m_s2: float | None = None
    swing_time_s: float | None = None
    swing_overlap: float = 1.0
    goal_tol_m: float = 0.05
    max_cycles: int = 400
    time_budget_s: float = 120.0
    min_step_fraction: float = 0.25
    max_fails_in_row: int = 8
    no_progress_cycles: int = 32
    balance_margin_frac: float = 0.01
    follow_support: bool = True
    com_target: str = "centroid"
    level_stride: float | None = None
    level_body_accel_m_s2: float | None = None
    level_clearance_m: float | None = None
    level_body_samples: int | None = None
    level_swing_samples: int | None = None
    overlap_worker: bool = True
    footholds: str = "lambda_t"
    restarts: int = 2
    theta: ThetaOptions = field(default_factory=ThetaOptions)
