"""Settings, genome layout and invalidity codes of the hopper model (Kang 1999); units: metres, seconds,
kilograms, radians. The model itself is in hopper.py (legs, eq 1-7), body.py (timeline, balance, eq 7-11) and
model.py (fitness, eq 12-14)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from charctl.experiments.hopper_ga.character import Body, body_from_config

GENE_BASE = ("l", "kappa", "theta0", "m", "alpha", "swing_angle", "swing_bend", "swing_gain", "bend_gain")

# Reasons an individual is physically impossible (bit flags; several may be set).
INVALID = {
    1: "HIP below the ground in stance",
    2: "leg compressed beyond the knee's flexion limit",
    4: "no lift-off within hopper.max_stance_s",
    8: "lift-off before the third stance frame",
    16: "flight time T not real (eq 4)",
    32: "flight time T outside (0, hopper.max_flight_s]",
    64: "leg through the ground",
    128: "swing knee hyper-extended or beyond its flexion limit",
    256: "balance joint beyond balance.angle_limit",
    512: "non-finite gene or gene outside its bounds",
    1024: "hip angle beyond +-90 degrees (foot above the hip)",
    2048: "no periodic gait (touchdown speed does not repeat)",
}
(
    HIP_GROUND,
    KNEE_LIMIT,
    NO_LIFTOFF,
    EARLY_LIFTOFF,
    T_NOT_REAL,
    T_RANGE,
    FOOT_GROUND,
    SWING_KNEE,
    BALANCE_LIMIT,
    BAD_GENE,
    HIP_RANGE,
    NO_PERIODIC,
) = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048)


def describe_invalid(code: int) -> str:
    """Human-readable list of the reasons in an invalidity bit mask."""
    return "; ".join(msg for bit, msg in INVALID.items() if int(code) & bit) or "valid"


@dataclass(frozen=True)
class Settings:
    """Everything the evaluation needs besides the genome (picklable: numpy arrays and scalars)."""

    speed: float  # m/s, x_dot (target speed)
    beta: float  # eq 14
    h: float  # s
    g: float  # m/s^2, negative
    touchdown_vy: float  # m/s
    periodic: bool
    periodic_tol: float  # m/s
    periodic_iterations: int
    periodic_scan: int
    max_touchdown_speed: float  # m/s
    max_stance_steps: int
    max_flight_s: float
    thigh_fraction: float
    knee_max_flexion: float  # rad
    ground_tol: float  # m
    angle_limit: float  # rad
    energy_scale: float
    predict_with_h: bool
    omega_floor: float  # rad/s
    body: Body
    low: np.ndarray = field(repr=False)  # (G,) gene bounds
    high: np.ndarray = field(repr=False)

    @property
    def gene_names(self) -> list[str]:
        return gene_names(self.body)


def gene_names(body: Body) -> list[str]:
    """l, kappa, theta0, m, alpha, 4 active-leg swing parameters, then one eta per balance DOF."""
    return list(GENE_BASE) + [f"eta.{n}" for n in body.dof_names]


def settings_from_config(cfg, speed: float | None = None, beta: float | None = None) -> Settings:
    body = body_from_config(cfg.character)
    b = cfg.bounds
    pairs = [b.l, b.kappa, b.theta0, b.m, b.alpha, b.swing_angle, b.swing_bend, b.swing_gain, b.bend_gain] + [
        b.eta
    ] * body.num_dofs
    return Settings(
        speed=float(cfg.speed if speed is None else speed),
        beta=float(cfg.beta if beta is None else beta),
        h=float(cfg.hopper.h),
        g=float(cfg.hopper.g),
        touchdown_vy=float(cfg.hopper.touchdown_vy),
        periodic=bool(cfg.hopper.periodic),
        periodic_tol=float(cfg.hopper.periodic_tol),
        periodic_iterations=int(cfg.hopper.periodic_iterations),
        periodic_scan=max(3, int(cfg.hopper.periodic_scan)),
        max_touchdown_speed=float(cfg.hopper.max_touchdown_speed),
        max_stance_steps=max(3, int(round(cfg.hopper.max_stance_s / cfg.hopper.h))),
        max_flight_s=float(cfg.hopper.max_flight_s),
        thigh_fraction=float(cfg.hopper.thigh_fraction),
        knee_max_flexion=float(np.radians(cfg.hopper.knee_max_flexion_deg)),
        ground_tol=float(cfg.hopper.ground_tolerance),
        angle_limit=float(cfg.balance.angle_limit),
        energy_scale=float(cfg.fitness.energy_scale),
        predict_with_h=bool(cfg.fitness.predict_with_h),
        omega_floor=float(cfg.fitness.omega_floor),
        body=body,
        low=np.array([p[0] for p in pairs], dtype=float),
        high=np.array([p[1] for p in pairs], dtype=float),
    )


# ---------------------------------------------------------------------------- genome
@dataclass
class Params:
    """Decoded genomes, each (N,) (eta: (N, D))."""

    l: np.ndarray
    kappa: np.ndarray
    theta0: np.ndarray
    m: np.ndarray
    alpha: np.ndarray
    swing_angle: np.ndarray  # active leg theta_c at touchdown (rad, <= 0: behind the hip)
    swing_bend: np.ndarray  # active leg theta_l at touchdown (rad)
    swing_gain: np.ndarray  # d theta_c(active) / d(theta0 - theta_c(idle)) during stance
    bend_gain: np.ndarray  # d theta_l(active) / d(theta0 - theta_c(idle)) during stance
    eta: np.ndarray  # (N, D) eq 11 response per balance DOF
    bad: np.ndarray  # (N,) bool: non-finite or out of bounds

    def take(self, rows: np.ndarray) -> Params:
        return Params(**{k: v[rows] for k, v in self.__dict__.items()})


def decode(genomes: np.ndarray, s: Settings) -> Params:
    """(N, G) genome rows -> Params. Out-of-bounds or non-finite rows are flagged, and clipped
    into the bounds so that the rest of the evaluation stays finite."""
    G = len(s.low)
    genomes = np.asarray(genomes, dtype=float).reshape(-1, G)
    finite = np.isfinite(genomes)
    inside = (genomes >= s.low) & (genomes <= s.high)
    bad = ~np.all(finite & inside, axis=1)
    g = np.clip(np.where(finite, genomes, s.low), s.low, s.high)
    cols = [g[:, i] for i in range(len(GENE_BASE))]
    return Params(*cols, eta=g[:, len(GENE_BASE) :], bad=bad)
