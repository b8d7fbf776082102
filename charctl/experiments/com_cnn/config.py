"""Structured config of the com-cnn experiment (docs/com-cnn.md; paper: "Motion generation using Center of
Mass", Park, Sohn, Lee, KCGS 2020). Defaults are the paper's values where it gives one; the keys
it leaves open carry a comment saying what we chose. Each value is stated here only;
conf/preset/com-cnn/<scale>.yaml state what a scale changes (steps, batch, clips)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

from charctl.config import BaseConfig
from charctl.config_fields import ranged

# Table 1 of the paper: mass per body part (total 62). Units are the paper's (only ratios matter).
PAPER_MASS_TABLE = {
    "Hips": 10.0,
    "Spine": 20.0,
    "Head": 5.0,
    "LeftArm": 2.0,
    "LeftForeArm": 1.5,
    "LeftHand": 0.5,
    "RightArm": 2.0,
    "RightForeArm": 1.5,
    "RightHand": 0.5,
    "LeftUpLeg": 5.0,
    "LeftLeg": 4.0,
    "LeftFoot": 0.5,
    "RightUpLeg": 5.0,
    "RightLeg": 4.0,
    "RightFoot": 0.5,
}
# Paper body part -> DeepMimic humanoid body (one to one: both skeletons have 15 parts).
HUMANOID_BODIES = {
    "Hips": "root",
    "Spine": "chest",
    "Head": "neck",
    "LeftArm": "left_shoulder",
    "LeftForeArm": "left_elbow",
    "LeftHand": "left_wrist",
    "RightArm": "right_shoulder",
    "RightForeArm": "right_elbow",
    "RightHand": "right_wrist",
    "LeftUpLeg": "left_hip",
    "LeftLeg": "left_knee",
    "LeftFoot": "left_ankle",
    "RightUpLeg": "right_hip",
    "RightLeg": "right_knee",
    "RightFoot": "right_ankle",
}
ALL_CLIPS = [
    "backflip",
    "cartwheel",
    "crawl",
    "dance_a",
    "dance_b",
    "getup_facedown",
    "getup_faceup",
    "jump",
    "kick",
    "punch",
    "roll",
    "run",
    "spin",
    "spinkick",
    "walk",
    "walker/turn_left0",
    "walker/turn_left1",
    "walker/turn_right0",
    "walker/turn_right1",
    "walker/walk_forward",
]


def conv_output_length(history: int, kernel: int, pool: int, layers: int) -> int:
    """Time steps left after `layers` x (valid conv of width `kernel`, max-pool of width `pool`).

    Paper Table 2: 90 -> 81 -> 40 -> 31 -> 15 -> 6 -> 3 for kernel 10, pool 2, three layers.
    """
    n = history
    for _ in range(layers):
        n = (n - kernel + 1) // pool
        if n < 1:
            return 0
    return n


@dataclass
class DataConfig:
    bvh_dir: str = ""  # a folder of .bvh files (any skeleton, y-up) replaces the DeepMimic clips when set
    clips: list[str] = field(default_factory=lambda: list(ALL_CLIPS))  # DeepMimic clips used (train + test)
    mirror: bool = True  # add the left/right mirrored copy of every DeepMimic clip (same split side)
    # held-out clips (never trained on; their mirrors are held out too)
    test_clips: list[str] = field(default_factory=lambda: ["walker/turn_right1", "crawl", "dance_b", "getup_faceup"])
    fps: float = ranged(30.0, gt=0)  # paper §3.2: every clip resampled to 30 fps
    history: int = ranged(90, ge=1)  # i, frames in M_t = {m_{t-i} .. m_{t-1}} (paper Table 4 best: 90)
    # reference frame of M_t, C_t and m_t: root_t = the root's heading frame at t (paper §3.2); root_prev = at t-1
    # (causal: needs nothing of frame t; our variant for generation)
    frame: Annotated[str, Literal["root_t", "root_prev"]] = "root_t"
    loop_min_seconds: float = ranged(6.0, ge=0)  # looping clips are repeated to at least this long (paper silent; ours)
    loop_blend_frames: int = ranged(6, ge=0)  # frames over which the pose jump at a loop seam is spread (ours)
    bvh_scale: float = ranged(1.0, ge=0)  # BVH positions x this = metres (0.01 for centimetre files)
    bvh_forward: list[float] = field(
        default_factory=lambda: [0.0, 0.0, 1.0]
    )  # root-local forward axis of BVH skeletons
    # precompute all training windows when they fit in this many MB (else per batch)
    window_cache_mb: int = ranged(512, ge=0)


@dataclass
class ComConfig:
    mass_table: dict[str, float] = field(default_factory=lambda: dict(PAPER_MASS_TABLE))  # paper Table 1
    humanoid_bodies: dict[str, str] = field(default_factory=lambda: dict(HUMANOID_BODIES))  # part -> humanoid body
    bvh_joints: dict[str, str] = field(
        default_factory=lambda: {k: k for k in PAPER_MASS_TABLE}
    )  # part -> BVH joint name


@dataclass
class ModelConfig:
    # filters per conv layer (paper Table 2); length = layers
    channels: list[int] = ranged(factory=lambda: [32, 64, 128], ge=1)
    kernel: int = ranged(10, ge=1)  # temporal kernel width w (paper Table 2)
    pool: int = ranged(2, ge=1)  # max-pooling width after every conv+ReLU (Table 2's 81->40, 31->15, 6->3)
    fc_hidden: int = ranged(512, ge=1)  # width of the first FC layer of P (paper silent; ours)
    # paper §3.3: P(K) = W1(W0 K + b0) + b1, no nonlinearity; "relu" is our variant
    fc_activation: Annotated[str, Literal["none", "relu"]] = "none"
    use_com: bool = True  # false = the history-only baseline (no C_t; the FC input is the 384-D Z alone)


@dataclass
class TrainConfig:
    steps: int = ranged(3000, ge=1)  # minibatch updates
    batch_size: int = ranged(64, ge=1)  # paper silent
    optimizer: Annotated[str, Literal["sgd", "adam", "adamw"]] = "sgd"  # paper §4: SGD | adam | adamw
    lr: float = ranged(0.01, gt=0)  # paper silent
    momentum: float = ranged(0.9, ge=0)  # SGD momentum (paper silent)
    weight_decay: float = ranged(0.0, ge=0)  # L2 weight decay of the optimiser (paper silent)
    grad_clip: float = ranged(10.0, ge=0)  # global gradient-norm clip (0 = off)
    # steps between the training-loss scalars in TensorBoard (and the last step's)
    log_every: int = ranged(20, ge=1)
    eval_every: int = ranged(500, ge=1)  # steps between held-out losses in TensorBoard
    checkpoint_every: int = ranged(1000, ge=1)  # steps between checkpoints (and one at the end / on Ctrl-C)
    # training windows (samples) between checkpoints also kept as checkpoints/samples_<n>.pt beside last.pt;
    # 0 = only last.pt
    keep_checkpoint_every: int = ranged(0, ge=0)
    torch_threads: int = ranged(2, ge=1)  # torch intra-op threads


@dataclass
class EvalConfig:
    # paper motion types -> DeepMimic class labels; labels not listed fall into "other"
    motion_types: dict[str, list[str]] = field(
        default_factory=lambda: {"walk": ["walk", "turn"], "crouch_walk": ["crawl"]}
    )
    # the paper's Table 5 errors per motion type, printed beside ours
    paper_table5: dict[str, float] = field(
        default_factory=lambda: {"walk": 0.415, "crouch_walk": 0.614, "other": 1.567}
    )
    horizon_s: float = ranged(3.0, gt=0)  # autoregressive rollouts: longest horizon on the error curve
    ar_stride: int = ranged(10, ge=1)  # frames between rollout starts within a held-out clip
    nn_pca_dims: int = ranged(64, ge=1)  # nearest-neighbour baseline: history compressed to this many PCA dims (ours)
    nn_com_weight: float = ranged(1.0, ge=0)  # relative weight of C_t against the whole history in the NN distance
    speed_frames: int = ranged(300, ge=1)  # generation-speed measurement: frames generated at batch 1 on the CPU


@dataclass
class GenerateConfig:
    seed_clip: str = "walker/walk_forward"  # clip whose first `history` frames seed the generation
    com_path: str = "circle:r=2,speed=1.2"  # default --com-path
    seconds: float = ranged(10.0, gt=0)  # default --seconds for procedural paths
    com_clamp: bool = True  # paper §5 safety: the input COM moves at most max_com_step per frame, direction kept
    max_com_step: float = ranged(0.1, gt=0)  # m per frame (3 m/s at 30 fps; paper gives no number, ours)
    crouch_drop: float = ranged(0.3, ge=0)  # m the COM is lowered from --crouch-at on
    crouch_ramp_s: float = ranged(1.0, ge=0)  # s over which the drop is ramped in
    # frame=root_t only: frames over which the COM's turning sets the root heading
    heading_window: int = ranged(10, ge=1)
    min_com_speed: float = ranged(0.2, ge=0)  # m/s below which the heading is held (frame=root_t only)


@dataclass
class Config(BaseConfig):
    experiment: str = "com-cnn"
    data: DataConfig = field(default_factory=DataConfig)
    com: ComConfig = field(default_factory=ComConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    generate: GenerateConfig = field(default_factory=GenerateConfig)

    @staticmethod
    def cross_checks(cfg) -> str | None:
        """Cross-key checks; a string describes the first problem.
        `BaseConfig.check` runs them after each field's declared choices and range."""
        if not cfg.model.channels:
            return "model.channels must be non-empty (one entry per conv layer)"
        if conv_output_length(cfg.data.history, cfg.model.kernel, cfg.model.pool, len(cfg.model.channels)) < 1:
            return (
                f"history {cfg.data.history} is too short for {len(cfg.model.channels)} conv layers of kernel "
                f"{cfg.model.kernel} with pooling {cfg.model.pool}"
            )
        if not cfg.data.bvh_dir:
            missing = [c for c in cfg.data.test_clips if c not in cfg.data.clips]
            if missing:
                return f"data.test_clips {missing} are not in data.clips"
            if not set(cfg.data.clips) - set(cfg.data.test_clips):
                return "every clip is a test clip: nothing left to train on"
        return None
