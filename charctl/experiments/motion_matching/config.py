"""Config schema of `motion-matching` (docs/motion-matching.md: the method, the paper's Table 1, the decisions).

Frame counts in `features.*` and `runtime.*` are *paper frames*: frames at `frame_unit_hz`
(120 Hz, the rate of the paper's capture data). They are converted to database frames with
round(n * data.fps / frame_unit_hz), so changing `data.fps` keeps every horizon in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal

from charctl.config import BaseConfig
from charctl.config_fields import ranged
from charctl.errors import CharctlError

NAME = "motion-matching"

DEFAULT_CLIPS = [
    "walker/walk_forward",
    "walker/turn_left0",
    "walker/turn_left1",
    "walker/turn_right0",
    "walker/turn_right1",
    "walk",
    "run",
]


@dataclass
class DataConfig:
    """Where the database comes from."""

    clips: list[str] = field(default_factory=lambda: list(DEFAULT_CLIPS))  # charctl clip names (humanoid)
    mirror: bool = True  # add every clip's left/right mirror (":mirror")
    fps: float = ranged(120.0, gt=0)  # database rate; the paper's data is 120 Hz
    # Looping clips (all shipped locomotion clips are 1.2 s loops) are unrolled: `loop_cycles_before`
    # cycles before and `loop_cycles_after` after the searchable cycle, so every searchable frame has
    # its past/future trajectory and playback can run on. Only one cycle per clip is searchable
    # (the others are exact repeats). Paper: silent (its data is one long take).
    loop_cycles_before: int = ranged(1, ge=0)
    loop_cycles_after: int = ranged(4, ge=1)  # unrolled cycles after the searchable one (see loop_cycles_before)
    # DeepMimic loops do not close exactly (seam jumps up to ~50 deg in the neck of turn_right0): the
    # seam residual of every joint is spread linearly over the cycle before unrolling.
    close_loops: bool = True
    bvh_dir: str = ""  # a folder of .bvh files (any skeleton, y-up) replaces `clips` when set
    bvh_scale: float = ranged(0.0, ge=0)  # file units -> metres; 0 = auto (0.01 when the root is higher than 5 units)
    # root-local forward axis: auto | +x | -x | +z | -z
    bvh_forward: Annotated[str, Literal["auto", "+x", "-x", "+z", "-z"]] = "auto"
    bvh_end_joints: list[str] = field(default_factory=list)  # pose end points; empty = two lowest leaves (feet)
    bvh_mirror: bool = False  # user BVH clips are not mirrored (left/right names are skeleton specific)


@dataclass
class FeatureConfig:
    """The feature vector (paper §3 and Fig. 7). Defaults = the paper's best setting (Table 1):
    4 future samples every 25 frames, position + velocity 0.8:0.2, discount 0.7."""

    future_samples: int = ranged(4, ge=1)  # Table 1 cases 1-7: 1..7 samples every 20 frames; cases 8-9: 4x25, 3x33
    future_spacing: int = ranged(25, ge=1)  # paper frames between future samples
    past_samples: int = ranged(0, ge=0)  # Table 1 cases 10-11 add the past trajectory (always worse in the paper)
    past_spacing: int = ranged(25, ge=1)  # paper frames between past samples
    position_weight: float = ranged(0.8, ge=0)  # position : velocity weights, Table 1 cases 12-15 (best 0.8:0.2)
    velocity_weight: float = ranged(0.2, ge=0)  # 0 removes the future-velocity block
    direction_weight: float = ranged(0.0, ge=0)  # future facing directions (Clavet/Holden); not in the paper -> 0
    past_weight: float = ranged(1.0, ge=0)  # weight of the past-position block when past_samples > 0
    # gamma: the i-th future sample's weight is gamma^(i-1) (cases 16-19, best 0.7)
    discount: float = ranged(0.7, gt=0, le=1)
    pose_weight: float = ranged(1.0, ge=0)  # weight of each pose block (root height, tilt, end points) vs trajectory
    end_points: list[str] = field(default_factory=lambda: ["right_ankle", "left_ankle"])  # humanoid bodies
    end_velocities: bool = True  # include end-point velocities (Clavet's foot velocities)
    # Heading of the root-local frame: the root's own yaw (paper) or its centred moving average over
    # this many seconds (a "simulation bone"); 0 = paper.
    heading_smoothing: float = ranged(0.0, ge=0)


@dataclass
class RuntimeConfig:
    """Online generation (paper §3)."""

    search_interval: int = ranged(20, ge=1)  # paper frames between searches (paper: 20 = ~0.15 s)
    # k: frames i of the current clip with |phase(i) - phase(cur)| < k are skipped
    exclude_window: int = ranged(20, ge=0)
    # Paper: the k frames around the current one are never chosen, so every search jumps.
    # true = Holden's variant: the current frame is a candidate too (continue if it is best).
    continue_if_best: bool = False
    end_buffer: int = ranged(20, ge=0)  # paper frames at the end of a non-looping clip that are never searched
    # bbox (Holden's bounding boxes, numba) | kdtree (scipy cKDTree) | brute (reference)
    index: Annotated[str, Literal["bbox", "kdtree", "brute"]] = "bbox"
    halflife: float = ranged(0.1, gt=0)  # s, inertialization: critically damped decay of the pose offset
    inertialize_root: bool = False  # also blend root velocity / turn rate (paper: raw root deltas)


@dataclass
class PathConfig:
    """Target paths (paper Fig. 5): circle, square (straights + 90 deg turns), star (sharp turns)."""

    # m/s of the target point; the database walks at 0.8-1.0 m/s (run: 3.6), 1.0 lags on curves
    speed: float = ranged(0.9, gt=0)
    circle_radius: float = ranged(3.0, gt=0)  # m
    square_side: float = ranged(5.0, gt=0)  # m
    star_points: int = ranged(5, ge=3)  # tips of the star path
    star_outer: float = ranged(3.0, gt=0)  # m, tip radius
    star_inner: float = ranged(1.5, gt=0)  # m, radius of the inner corners
    laps: float = ranged(1.0, gt=0)  # how far the target travels: laps of a closed path (open CSV paths: to the end)
    # Controller: desired future positions = target point at t + dt_i, plus the current offset of the
    # character from the target decayed with this half-life (s). 0 = raw target points.
    correction_halflife: float = ranged(0.0, ge=0)


@dataclass
class SweepConfig:
    """`charctl eval motion-matching --sweep`: Table 1 cases on the three paths."""

    paths: list[str] = field(default_factory=lambda: ["circle", "square", "star"])  # target paths swept
    cases: list[int] = field(default_factory=list)  # empty = all 19
    # Rollouts per path, started at evenly spaced gait phases of the best-matching clip; errors are
    # pooled over their frames. One rollout is chaotic (a 2% change of speed moves a case's mean
    # error by ~0.05 m), so several starts make the ranking of cases meaningful. Paper: silent.
    starts: int = ranged(4, ge=1)
    plots: bool = True  # PNG of generated vs target paths per case


@dataclass
class Config(BaseConfig):
    DEVICES = ("cpu",)  # numpy only: device=cuda is refused (charctl.config.check_device_name), auto = cpu
    experiment: str = "motion-matching"
    path: str = "star"  # circle | square | star | FILE.csv (x,z waypoints, metres)
    case: str = ""  # "" = use features.*; "1".."19" = a Table 1 case; "best" = best case of the latest sweep
    frame_unit_hz: float = ranged(120.0, gt=0)  # rate of the frame counts in features.*/runtime.* (paper data: 120 Hz)
    data: DataConfig = field(default_factory=DataConfig)
    features: FeatureConfig = field(default_factory=FeatureConfig)
    runtime: RuntimeConfig = field(default_factory=RuntimeConfig)
    paths: PathConfig = field(default_factory=PathConfig)
    sweep: SweepConfig = field(default_factory=SweepConfig)

    @staticmethod
    def cross_checks(cfg) -> str | None:
        """A one-line problem with the config, or None: the cross-field rules.
        `BaseConfig.check` runs them after each field's declared choices and range."""
        f, p = cfg.features, cfg.paths
        if f.position_weight + f.velocity_weight + f.direction_weight <= 0:
            return "at least one of features.position_weight/velocity_weight/direction_weight must be > 0"
        if p.star_inner >= p.star_outer:
            return "path sizes must be > 0 and paths.star_inner < paths.star_outer"
        return None


def load_config(targets: list[str], overrides: list[str]):
    """The config of a run directory (if one is given) or the composed experiment config."""
    from charctl.config import compose_config
    from charctl.runs import open_run

    runs = [t for t in targets if t != NAME]
    if len(runs) > 1:
        raise CharctlError("motion-matching evaluates one run directory (or the experiment name) at a time")
    if runs:
        return open_run(runs[0], Config, overrides).cfg
    return compose_config(NAME, overrides, Config)
