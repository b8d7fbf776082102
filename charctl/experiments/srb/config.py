"""Structured config of the srb experiment (docs/srb.md: method, the paper's numbers, decisions).

The defaults here are the paper's values (each stated once, with the section it comes from);
conf/preset/srb/<scale>.yaml state only what a scale changes. Decisions where the paper
is silent or garbled are marked "decision" and explained in docs/srb.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

from charctl.config import BaseConfig
from charctl.config_fields import ranged
from charctl.rl.config import PPOConfig, check_ppo


@dataclass
class BodyConfig:
    """The single rigid body (paper §4)."""

    mass: float = ranged(60.0, gt=0)  # kg, paper §4
    # frame of the reference clip whose composite inertia (pelvis frame) is scaled to `mass`
    inertia_pose_frame: int = ranged(0, ge=0)
    # Coulomb mu of the linearised cone (decision: the MuJoCo humanoid's floor friction)
    friction: float = ranged(1.0, gt=0)


@dataclass
class ReferenceConfig:
    """Reference motion and the contact schedule derived from it (paper §4)."""

    clip: str = "walk"  # charctl clip spec; the pelvis (root) trajectory is the SRB's desired COM frame
    contact_height: float = 0.03  # m: a foot is in stance when its lower sole point is below this ...
    contact_speed: float = 1.0  # m/s: ... and that point's horizontal speed is below this (decision)
    min_phase_frames: int = ranged(3, ge=0)  # stance/swing runs shorter than this are merged (mocap glitches)


@dataclass
class TrackingConfig:
    """QP tracker (paper §7): q_dd_d = clamp(a (p_d - p) + b (v_d - v), lo, hi); min ||q_dd - q_dd_d||_W."""

    kp: float = ranged(120.0, gt=0)  # a, paper §7
    kd: float = ranged(35.0, gt=0)  # b, paper §7
    acc_min: float = -400.0  # min, paper §7
    acc_max: float = 400.0  # max, paper §7
    # W entries of the 3 linear COM accelerations (decision, see docs: the text's "1-6" is garbled)
    w_linear: float = ranged(1.0, ge=0)
    w_angular: float = ranged(1.0, ge=0)  # W entries of the 3 angular accelerations
    force_reg: float = ranged(1e-6, ge=0)  # weight of ||lambda / m||^2 (m/s^2)^2: keeps the QP strictly convex
    # N m per axis of the free body torque tau (0 = contact forces only; decision)
    torque_limit: float = ranged(30.0, ge=0)
    torque_reg: float = ranged(1e-3, ge=0)  # weight of ||I^-1 tau||^2 (rad/s^2)^2: tau is almost free inside its bound
    # daqp (direct C call, hot path) | qpsolvers:daqp | qpsolvers:quadprog
    solver: Annotated[str, Literal["daqp", "qpsolvers:daqp", "qpsolvers:quadprog"]] = "daqp"
    substeps: int = ranged(1, ge=1)  # QP solves + integration steps per control step (paper: one per frame)


@dataclass
class ActionConfig:
    """Action (paper §5.1): feet (x, z) in the SRB heading frame, relative lin/ang velocity."""

    # reference: foot = ref foot (heading frame) + action | paper: COM + R_y (action + k)
    foot_mode: Annotated[str, Literal["reference", "paper"]] = "reference"
    foot_offset: float = 0.07  # |k| of paper §6 (lateral, m), used by foot_mode=paper
    foot_scale: float = 0.1  # m per unit of policy output
    lin_vel_scale: float = 0.5  # m/s per unit
    ang_vel_scale: float = 0.5  # rad/s per unit


@dataclass
class TouchdownConfig:
    """Early / late touch-down handling by shifting the reference frame (paper §6)."""

    enabled: bool = True  # shift the reference at early / late touch-downs (off: the reference runs on its clock)
    # m: late when y_srb > y_ref + margin at a scheduled touch-down -> the reference waits
    late_margin: float = ranged(0.0, ge=0)
    # frames the reference may wait for one touch-down (decision; the paper gives none)
    max_delay: int = ranged(6, ge=0)
    # m: early when y_srb < (ref pelvis height at touch-down) - margin during swing
    early_margin: float = ranged(0.03, ge=0)
    # early touch-down only in the last half of a swing (decision: no jump right after lift-off)
    early_min_swing: float = ranged(0.5, ge=0, le=1)
    zero_vertical_velocity: bool = (
        True  # early touch-down: "set the COM y to 0" read as the downward velocity (decision)
    )


@dataclass
class RewardConfig:
    """r = max(0, w_s r_s + w_m r_m), r_m = -(pose + end-effector + velocity errors) (paper §5.2)."""

    w_stand: float = ranged(5.0, ge=0)  # w_s, paper §5.2
    w_mimic: float = ranged(0.3, ge=0)  # w_m, paper §5.2
    # pose: ||d_srb - d_ref||^2 (m^2) weight (decision: the paper's kernels are not in the text)
    k_disp: float = ranged(1000.0, ge=0)
    k_rot: float = ranged(100.0, ge=0)  # pose: angle(q_srb (-) q_ref)^2 (rad^2) weight
    # end-effector: sum ||c_srb - c_ref||^2 over stance contact points and the next COM (m^2)
    k_ee: float = ranged(10.0, ge=0)
    k_vel: float = ranged(1.0, ge=0)  # velocity: ||v_srb - v_ref||^2 ((m/s)^2)


@dataclass
class TerminationConfig:
    """Episode end (paper §5.3): y outside [min(r y_ref, y_abs), y_max], tilt > max, step limit."""

    max_height: float = ranged(2.0, gt=0)  # m, paper §5.3
    min_height_ratio: float = ranged(0.7, ge=0, le=1)  # r in min(0.7 y_ref(t+1), 0.2), paper §5.3
    min_height_abs: float = 0.2  # m, the 0.2 of the same formula
    max_tilt_deg: float = 70.0  # paper §5.3
    max_steps: int = ranged(90, ge=1)  # paper §5.3 (training episodes)


@dataclass
class PushConfig:
    """Push-robustness protocol (paper §9, Table 1). See push.PushCase for the exact semantics."""

    forces: list[float] = ranged(factory=lambda: [float(f) for f in range(100, 1600, 100)], ge=0)  # N, "impulse" cells
    # s a "100 N impulse" is held (decision, docs/srb.md: 0.2 s reconciles paper §9 with Table 1)
    impulse_duration: float = ranged(0.2, gt=0)
    sustained_force: float = ranged(100.0, gt=0)  # N, Table 1
    durations: list[float] = ranged(factory=lambda: [0.01, 0.1, 0.2, 0.3, 0.4, 1.0], gt=0)  # s, Table 1
    directions: list[float] = field(
        default_factory=lambda: [0.0, 90.0, 180.0, 270.0]
    )  # deg in the heading frame, 0 = forward, 90 = left
    phases: list[float] = ranged(factory=lambda: [0.0, 0.25, 0.5, 0.75], ge=0, lt=1)  # gait phase of the push onset
    trials: int = ranged(5, ge=1)  # K trials per cell (CLI -k overrides)
    settle: float = ranged(1.0, ge=0)  # s of unperturbed walking before the push window
    observe: float = ranged(2.0, gt=0)  # s after the push ends the character must stay up
    init_noise: float = ranged(0.05, ge=0)  # SRB trials: std of the initial COM velocity perturbation (m/s and rad/s)
    # "largest survived force": the largest force whose survival rate is >= this
    survive_rate: float = ranged(0.5, ge=0, le=1)
    zero_action_column: bool = (
        True  # also run the protocol with zero actions: what the QP tracker does without the policy
    )
    baseline_run: str = (
        ""  # cgail run directory for the full-body column, or "auto" = the latest AMP walk run under output_root
    )


@dataclass
class TrainConfig:
    total_samples: int = ranged(200_000_000, ge=1)  # paper §8: 2e8
    num_envs: int = ranged(32, ge=1)  # environments stepped together
    # steps per env per update: num_envs * rollout_steps = samples per update (paper: 1024)
    rollout_steps: int = ranged(32, ge=1)
    checkpoint_every: int = ranged(20, ge=1)  # iterations between checkpoints
    torch_threads: int = ranged(1, ge=1)  # torch intra-op threads of the PPO update


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
    def cross_checks(cfg) -> str | None:
        """Cross-field checks (called by charctl.config.validate); a message or None.
        `BaseConfig.check` runs them after each field's declared choices and range."""
        if cfg.ppo.mirror_loss > 0:
            return "ppo.mirror_loss: srb defines no left/right mirror of its policy (only cgail does)"
        return check_ppo(cfg.ppo)
