"""Structured config of the hopper-ga experiment (docs/hopper-ga.md, Kang 1999). Each value is stated
here only, with the equation it belongs to; conf/preset/hopper-ga/<scale>.yaml state what a scale
changes. Units: metres, seconds, kilograms, radians."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated, Literal

from charctl.config import BaseConfig
from charctl.config_fields import ranged


@dataclass
class HopperConfig:
    """The planar spring hopper (eq 1-6)."""

    h: float = ranged(0.01, gt=0)  # s, frame step h of eq 2 and eq 10 (paper Fig 3.5/3.7: 0.01)
    g: float = ranged(-9.81, lt=0)  # m/s^2, gravity (negative, as in eq 2 and eq 4)
    touchdown_vy: float = 0.0  # m/s, HIP vertical speed at the first touchdown (eq 1 gives positions only)
    periodic: bool = False  # true: solve the touchdown speed of a steady (repeating) cycle; see docs
    periodic_tol: float = 0.001  # m/s, |landing - touchdown speed| accepted as periodic
    periodic_scan: int = ranged(9, ge=1)  # touchdown speeds scanned in [-max_touchdown_speed, 0] for a sign change
    periodic_iterations: int = ranged(12, ge=1)  # regula-falsi steps in the bracket; no convergence = invalid
    max_touchdown_speed: float = 6.0  # m/s, search range of the periodic touchdown speed
    max_stance_s: float = ranged(1.0, gt=0)  # s, a stance that has not lifted off by then is invalid
    max_flight_s: float = ranged(1.0, gt=0)  # s, a flight time T above this is invalid
    # |HIP-JOINT| / l; |JOINT-FOOT| = l - |HIP-JOINT| (paper Fig 3.3: knee mid-leg)
    thigh_fraction: float = ranged(0.5, ge=0.2, le=0.5)
    # knee flexion limit; a tighter fold (d too short) is invalid
    knee_max_flexion_deg: float = ranged(150.0, gt=0, lt=180)
    ground_tolerance: float = 0.005  # m, a foot lower than -tolerance is "leg through the ground" -> invalid


@dataclass
class SegmentConfig:
    """One upper-body joint and the segment it moves (eq 8 mass point at `com` along the segment)."""

    name: str = "chest"
    parent: str = "root"  # "root" = the pelvis
    offset: list[float] = field(default_factory=lambda: [0.0, 0.1, 0.0])  # m, joint position in the parent's frame
    direction: list[float] = field(
        default_factory=lambda: [0.0, 1.0, 0.0]
    )  # unit vector of the segment in the rest pose
    length: float = ranged(0.45, gt=0)  # m
    mass: float = ranged(0.355, gt=0)  # fraction of character.mass
    com: float = 0.5  # COM position along the segment, fraction of its length from the joint
    axes: str = "zx"  # balance DOFs of this joint: z = sagittal (eq 10-11 zd_b), x = lateral (xd_b)


def _default_upper() -> list[SegmentConfig]:
    # Winter (2009) segment mass fractions; lengths for a ~1.75 m adult.
    return [
        SegmentConfig("chest", "root", [0.0, 0.10, 0.0], [0.0, 1.0, 0.0], 0.45, 0.355, 0.5, "zx"),
        SegmentConfig("neck", "chest", [0.0, 0.45, 0.0], [0.0, 1.0, 0.0], 0.25, 0.081, 0.5, "zx"),
        SegmentConfig("right_shoulder", "chest", [0.0, 0.40, 0.18], [0.0, -1.0, 0.0], 0.29, 0.028, 0.436, "zx"),
        SegmentConfig("right_elbow", "right_shoulder", [0.0, -0.29, 0.0], [0.0, -1.0, 0.0], 0.40, 0.022, 0.4, "z"),
        SegmentConfig("left_shoulder", "chest", [0.0, 0.40, -0.18], [0.0, -1.0, 0.0], 0.29, 0.028, 0.436, "zx"),
        SegmentConfig("left_elbow", "left_shoulder", [0.0, -0.29, 0.0], [0.0, -1.0, 0.0], 0.40, 0.022, 0.4, "z"),
    ]


@dataclass
class CharacterConfig:
    """The 11-joint character (paper Fig 2.1): root (pelvis), chest, neck, 2 x (shoulder, elbow),
    2 x (hip, knee). Leg segment lengths come from the gene l; everything else is fixed here."""

    mass: float = ranged(70.0, gt=0)  # kg, total body mass (eq 8 M_i = fraction * mass)
    pelvis_mass: float = 0.142  # fraction; the pelvis mass point sits at HIP
    hip_half_width: float = 0.09  # m, each hip joint is this far from HIP along z (right = +z)
    thigh_mass: float = 0.100  # fraction, per leg
    shank_mass: float = 0.061  # fraction, per leg (shank + foot)
    thigh_com: float = 0.433  # COM along the thigh from the hip
    shank_com: float = 0.5  # COM along the shank from the knee
    upper: list[SegmentConfig] = field(default_factory=_default_upper)  # upper-body segments (mass, length)


@dataclass
class BoundsConfig:
    """GA gene bounds [low, high] (the paper gives none; see docs/hopper-ga.md)."""

    l: list[float] = ranged(factory=lambda: [0.75, 1.05], gt=0)  # m, leg length (human scale)
    kappa: list[float] = ranged(factory=lambda: [2000.0, 12000.0], gt=0)  # N/m, spring constant
    theta0: list[float] = ranged(factory=lambda: [0.1, 0.8], gt=0, lt=math.pi / 2)  # rad, touchdown angle (eq 1)
    m: list[float] = ranged(factory=lambda: [40.0, 100.0], gt=0)  # kg, HIP mass of eq 2
    alpha: list[float] = field(default_factory=lambda: [0.55, 1.0])  # eq 6: extremum of B_c at alpha*T
    swing_angle: list[float] = field(default_factory=lambda: [-1.2, 0.0])  # rad, active leg theta_c at stance start
    swing_bend: list[float] = field(default_factory=lambda: [0.0, 1.2])  # rad, active leg theta_l at stance start
    swing_gain: list[float] = field(
        default_factory=lambda: [0.0, 3.0]
    )  # active theta_c = angle + gain*(theta0 - idle theta_c)
    bend_gain: list[float] = field(
        default_factory=lambda: [-2.0, 2.0]
    )  # active theta_l = bend + gain*(theta0 - idle theta_c)
    eta: list[float] = field(default_factory=lambda: [0.0, 10.0])  # eq 11 response, one gene per balance DOF


@dataclass
class BalanceConfig:
    angle_limit: float = 1.2  # rad, |balance joint angle| above this = the body folds over -> invalid


@dataclass
class FitnessConfig:
    """eq 12-14."""

    # E_r unit (kg m^2 s^-3 per m): the GA's lowest E_r at 2-10 m/s is ~0.15 of it; see docs
    energy_scale: float = ranged(4.0e5, gt=0)
    predict_with_h: bool = True  # gamma's predicted speed is theta_dot_s + theta_ddot_s * h (paper omits h)
    omega_floor: float = ranged(0.1, gt=0)  # rad/s, softens max/min in gamma when a speed is near zero


@dataclass
class GAConfig:
    population: int = ranged(100, ge=4)  # paper Fig 5.7: 100 individuals
    generations: int = ranged(100, ge=1)  # paper Fig 5.7: 100 generations
    tournament: int = ranged(2, ge=1)  # DEAP selTournament size
    elite: int = ranged(2, ge=1)  # best individuals copied unchanged into the next generation (< population)
    cxpb: float = ranged(0.7, ge=0, le=1)  # crossover probability per pair (DEAP cxSimulatedBinaryBounded)
    mutpb: float = ranged(0.5, ge=0, le=1)  # mutation probability per individual (DEAP mutPolynomialBounded)
    cx_eta: float = 15.0  # SBX crowding degree
    mut_eta: float = 10.0  # polynomial mutation crowding degree
    indpb: float = ranged(0.2, ge=0, le=1)  # per-gene mutation probability
    init_retries: int = ranged(50, ge=1)  # generation 0: re-draw invalid individuals up to this many rounds


@dataclass
class TrainConfig:
    """Checkpoints of the GA run (the shared runner, charctl.rl.runner; one iteration = one generation)."""

    checkpoint_every: int = ranged(1, ge=1)  # generations between checkpoints/last.pt (and one at the end / on Ctrl-C)
    # evaluations between checkpoints also kept as checkpoints/samples_<n>.pt beside last.pt; 0 = only last.pt
    keep_checkpoint_every: int = ranged(0, ge=0)


@dataclass
class RuntimeConfig:
    # local (vectorised numpy) | process (multiprocessing pool) | ray
    kind: Annotated[str, Literal["local", "process", "ray"]] = "local"
    workers: int = ranged(2, ge=1)  # process/ray: parallel workers (the population is split into this many chunks)
    address: str = ""  # ray: cluster address ("" = start Ray on this machine)


@dataclass
class LimpConfig:
    speed_factor: float = ranged(1.5, gt=0)  # Fig 3.13: HIP speed multiplier while the limping (left) leg supports
    cycles: int = ranged(8, ge=2)  # cycles simulated for the limp test and the COM path


@dataclass
class ExportConfig:
    fps: float = ranged(60.0, gt=0)  # BVH frame rate
    video_fps: float = ranged(30.0, gt=0)  # mp4 frame rate
    seconds: float = ranged(3.0, gt=0)  # length of the exported running motion (rounded up to whole cycles)


@dataclass
class Config(BaseConfig):
    DEVICES = ("cpu",)  # numpy only: device=cuda is refused (charctl.config.check_device_name), auto = cpu
    experiment: str = "hopper-ga"
    # m/s, target running speed = HIP speed x_dot of eq 2-3 (conceptual control parameter)
    speed: float = ranged(5.0, gt=0)
    beta: float = ranged(0.0, ge=0, lt=1)  # briskness, eq 14, 0 <= beta < 1
    hopper: HopperConfig = field(default_factory=HopperConfig)
    character: CharacterConfig = field(default_factory=CharacterConfig)
    balance: BalanceConfig = field(default_factory=BalanceConfig)
    bounds: BoundsConfig = field(default_factory=BoundsConfig)
    fitness: FitnessConfig = field(default_factory=FitnessConfig)
    ga: GAConfig = field(default_factory=GAConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    runtime: RuntimeConfig = field(default_factory=RuntimeConfig)
    limp: LimpConfig = field(default_factory=LimpConfig)
    export: ExportConfig = field(default_factory=ExportConfig)

    @staticmethod
    def cross_checks(cfg) -> str | None:
        """Cross-field checks; returns a message or None.
        `BaseConfig.check` runs them after each field's declared choices and range."""
        for part in (_check_bounds, _check_ga, _check_character):
            if (msg := part(cfg)) is not None:
                return msg
        return None


def _check_bounds(cfg) -> str | None:
    """Every gene's [low, high] search bounds (l, kappa, m > 0 and theta0 inside (0, pi/2) are declared on
    the fields, for each element)."""
    for name in (
        "l",
        "kappa",
        "theta0",
        "m",
        "alpha",
        "swing_angle",
        "swing_bend",
        "swing_gain",
        "bend_gain",
        "eta",
    ):
        b = list(getattr(cfg.bounds, name))
        if len(b) != 2 or not b[0] < b[1]:
            return f"bounds.{name} must be [low, high] with low < high, got {b}"
    a = cfg.bounds.alpha
    if a[0] <= 0.5 <= a[1]:
        return f"bounds.alpha must not contain 0.5 (B_c of eq 6 is singular there), got {list(a)}"
    return None


def _check_ga(cfg) -> str | None:
    """Elitism against the population size (each one's own range is declared on its field)."""
    if cfg.ga.elite >= cfg.ga.population:
        return "ga.elite must lie in [1, population) (elitism keeps the best individual)"
    return None


def _check_character(cfg) -> str | None:
    """The upper-body joint list: unique names, parents listed earlier, axes z/x, 3-vectors."""
    names = [s.name for s in cfg.character.upper]
    if not names:
        return "character.upper must list the upper-body joints (chest, neck, shoulders, elbows)"
    if len(set(names)) != len(names):
        return f"character.upper joint names must be unique, got {names}"
    for s in cfg.character.upper:
        if s.parent != "root" and s.parent not in names[: names.index(s.name)]:
            return f"character.upper: {s.name!r} has parent {s.parent!r}, which must be 'root' or an earlier joint"
        if set(s.axes) - set("zx"):
            return f"character.upper: {s.name!r} axes must use only 'z' and 'x', got {s.axes!r}"
        if len(s.offset) != 3 or len(s.direction) != 3:
            return f"character.upper: {s.name!r} offset and direction must have 3 numbers"
    return None
