"""Structured config of the srb experiment (docs/srb.md: method, the paper's numbers, decisions).

The defaults here are the paper's values (each stated once, with the section it comes from);
conf/preset/srb/<scale>.yaml state only what a scale changes. Decisions where the paper
is silent or garbled are marked "decision" and explained in docs/srb.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from charctl.config import BaseConfig
from charctl.rl.config import PPOConfig, check_ppo


@dataclass
class BodyConfig:
    """The single rigid body (paper §4)."""

    mass: float = 60.0  # kg, paper §4
    inertia_pose_frame: int = (
        0  # frame of the reference clip whose composite inertia (pelvis frame) is scaled to `mass`
    )
    friction: float = 1.0  # Coulomb mu of the linearised cone (decision: the MuJoCo humanoid's floor friction)


@dataclass
class ReferenceConfig:
    """Reference motion and the contact schedule derived from it (paper §4)."""

    clip: str = "walk"  # charctl clip spec; the pelvis (root) trajectory is the SRB's desired COM frame
    contact_height: float = 0.03  # m: a foot is in stance when its lower sole point is below this ...
    contact_speed: float = 1.0  # m/s: ... and that point's horizontal speed is below this (decision)
    min_phase_frames: int = 3  # stance/swing runs shorter than this are merged (mocap glitches)


@dataclass
class TrackingConfig:
    """QP tracker (paper §7): q_dd_d = clamp(a (p_d - p) + b (v_d - v), lo, hi); min ||q_dd - q_dd_d||_W."""

    kp: float = 120.0  # a, paper §7
    kd: float = 35.0  # b, paper §7
    acc_min: float = -400.0  # min, paper §7
    acc_max: float = 400.0  # max, paper §7
    w_linear: float = (
        1.0  # W entries of the 3 linear COM accelerations (decision, see docs: the text's "1-6" is garbled)
    )
    w_angular: float = 1.0  # W entries of the 3 angular accelerations
    force_reg: float = 1e-6  # weight of ||lambda / m||^2 (m/s^2)^2: keeps the QP strictly convex
    torque_limit: float = 30.0  # N m per axis of the free body torque tau (0 = contact forces only; decision)
    torque_reg: float = 1e-3  # weight of ||I^-1 tau||^2 (rad/s^2)^2: tau is almost free inside its bound
    solver: str = "daqp"  # daqp (direct C call, hot path) | qpsolvers:daqp | qpsolvers:quadprog
    substeps: int = 1  # QP solves + integration steps per control step (paper: one per frame)


@dataclass
class ActionConfig:
    """Action (paper §5.1): feet (x, z) in the SRB heading frame, relative lin/ang velocity."""

    foot_mode: str = "reference"  # reference: foot = ref foot (heading frame) + action | paper: COM + R_y (action + k)
    foot_offset: float = 0.07  # |k| of paper §6 (lateral, m), used by foot_mode=paper
    foot_scale: float = 0.1  # m per unit of policy output
    lin_vel_scale: float = 0.5  # m/s per unit
    ang_vel_scale: float = 0.5  # rad/s per unit


@dataclass
class TouchdownConfig:
    """Early / late touch-down handling by shifting the reference frame (paper §6)."""

    enabled: bool = True  # shift the reference at early / late touch-downs (off: the reference runs on its clock)
    late_margin: float = 0.0  # m: late when y_srb > y_ref + margin at a scheduled touch-down -> the reference waits
    max_delay: int = 6  # frames the reference may wait for one touch-down (decision; the paper gives none)
    early_margin: float = 0.03  # m: early when y_srb < (ref pelvis height at touch-down) - margin during swing
    early_min_swing: float = (
        0.5  # early touch-down only in the last half of a swing (decision: no jump right after lift-off)
    )
    zero_vertical_velocity: bool = (
        True  # early touch-down: "set the COM y to 0" read as the downward velocity (decision)
    )


@dataclass
class RewardConfig:
    """r = max(0, w_s r_s + w_m r_m), r_m = -(pose + end-effector + velocity errors) (paper §5.2)."""

    w_stand: float = 5.0  # w_s, paper §5.2
    w_mimic: float = 0.3  # w_m, paper §5.2
    k_disp: float = 1000.0  # pose: ||d_srb - d_ref||^2 (m^2) weight (decision: the paper's kernels are not in the text)
    k_rot: float = 100.0  # pose: angle(q_srb (-) q_ref)^2 (rad^2) weight
    k_ee: float = 10.0  # end-effector: sum ||c_srb - c_ref||^2 over stance contact points and the next COM (m^2)
    k_vel: float = 1.0  # velocity: ||v_srb - v_ref||^2 ((m/s)^2)


@dataclass
class TerminationConfig:
    """Episode end (paper §5.3): y outside [min(r y_ref, y_abs), y_max], tilt > max, step limit."""

    max_height: float = 2.0  # m, paper §5.3
    min_height_ratio: float = 0.7  # r in min(0.7 y_ref(t+1), 0.2), paper §5.3
    min_height_abs: float = 0.2  # m, the 0.2 of the same formula
    max_tilt_deg: float = 70.0  # paper §5.3
    max_steps: int = 90  # paper §5.3 (training episodes)


@dataclass
class PushConfig:
    """Push-robustness protocol (paper §9, Table 1). See push.PushCase for the exact semantics."""

    forces: list[float] = field(default_factory=lambda: [float(f) for f in range(100, 1600, 100)])  # N, "impulse" cells
    impulse_duration: float = (
        0.2  # s a "100 N impulse" is held (decision, docs/srb.md: 0.2 s reconciles paper §9 with Table 1)
    )
    sustained_force: float = 100.0  # N, Table 1
    durations: list[float] = field(default_factory=lambda: [0.01, 0.1, 0.2, 0.3, 0.4, 1.0])  # s, Table 1
    directions: list[float] = field(
        default_factory=lambda: [0.0, 90.0, 180.0, 270.0]
    )  # deg in the heading frame, 0 = forward, 90 = left
    phases: list[float] = field(
        default_factory=lambda: [0.0, 0.25, 0.5, 0.75]
    )  # gait phase in [0, 1) of the push onset
    trials: int = 5  # K trials per cell (CLI -k overrides)
    settle: float = 1.0  # s of unperturbed walking before the push window
    observe: float = 2.0  # s after the push ends the character must stay up
    init_noise: float = 0.05  # SRB trials: std of the initial COM velocity perturbation (m/s and rad/s)
    survive_rate: float = 0.5  # "largest survived force": the largest force whose survival rate is >= this
    zero_action_column: bool = (
        True  # also run the protocol with zero actions: what the QP tracker does without the policy
    )
    baseline_run: str = (
        ""  # cgail run directory for the full-body column, or "auto" = the latest AMP walk run under output_root
    )


@dataclass
class TrainConfig:
    total_samples: int = 200_000_000  # paper §8: 2e8
    num_envs: int = 32  # environments stepped together
    rollout_steps: int = 32  # steps per env per update: num_envs * rollout_steps = samples per update (paper: 1024)
    checkpoint_every: int = 20  # iterations between checkpoints
    torch_threads: int = 1  # torch intra-op threads of the PPO update


def default_ppo() -> PPOConfig:
    """Paper §5/§8: 4 x 64 tanh, m = 1024 (train.num_envs x train.rollout_steps), n = 256, gamma 0.995,
    lr 1e-4; lambda 0.95 and eps 0.2 are also the paper's and PPOConfig's defaults. Decisions (paper
    silent, docs/srb.md): a fixed Gaussian std of 0.3 policy units; 5 epochs, value weight 0.5 and
    grad-norm 1 as PPOConfig."""
    return PPOConfig(
        lr=1e-4, gamma=0.995, minibatch_size=256, hidden=[64, 64, 64, 64], activation="tanh", action_std=0.3
    )


@dataclass
class Config(BaseConfig):
    experiment: str = "srb"
    body: BodyConfig = field(default_factory=BodyConfig)
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    action: ActionConfig = field(default_factory=ActionConfig)
    touchdown: TouchdownConfig = field(default_factory=TouchdownConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    termination: TerminationConfig = field(default_factory=TerminationConfig)
    ppo: PPOConfig = field(default_factory=default_ppo)
    train: TrainConfig = field(default_factory=TrainConfig)
    push: PushConfig = field(default_factory=PushConfig)

    @staticmethod
    def check(cfg) -> str | None:
        """Cross-field checks (called by charctl.config.validate); a message or None."""
        from charctl.experiments.srb.qp import SOLVERS

        if (msg := check_ppo(cfg.ppo)) is not None:
            return msg
        if cfg.tracking.solver not in SOLVERS:
            return f"tracking.solver={cfg.tracking.solver!r}; choose one of {', '.join(SOLVERS)}"
        if cfg.action.foot_mode not in ("reference", "paper"):
            return f"action.foot_mode={cfg.action.foot_mode!r}; choose reference or paper"
        if cfg.tracking.substeps < 1 or cfg.train.num_envs < 1 or cfg.train.rollout_steps < 1:
            return "tracking.substeps, train.num_envs and train.rollout_steps must be >= 1"
        if cfg.body.mass <= 0 or cfg.body.friction <= 0:
            return "body.mass and body.friction must be positive"
        if cfg.push.trials < 1:
            return "push.trials must be >= 1"
        if any(not 0.0 <= p < 1.0 for p in cfg.push.phases):
            return "push.phases must lie in [0, 1)"
        return None
