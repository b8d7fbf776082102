"""The srb config values the environment's step reads, copied once into plain floats and ints (no OmegaConf
attribute reads in the hot path): PD tracking, the action, touch-down handling, reward and termination."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class EnvParams:
    """The config values the step reads, copied once into plain floats (no OmegaConf in the hot path)."""

    kp: float
    kd: float
    acc_min: float
    acc_max: float
    substeps: int
    solver: str
    foot_mode: str
    foot_offset: float
    td_enabled: bool
    late_margin: float
    max_delay: int
    early_margin: float
    early_min_swing: float
    zero_vertical_velocity: bool
    w_stand: float
    w_mimic: float
    k_disp: float
    k_rot: float
    k_ee: float
    k_vel: float
    max_height: float
    min_height_ratio: float
    min_height_abs: float
    max_tilt: float  # radians

    @classmethod
    def from_cfg(cls, cfg) -> EnvParams:
        t, a, td, r, term = cfg.tracking, cfg.action, cfg.touchdown, cfg.reward, cfg.termination
        return cls(
            kp=float(t.kp),
            kd=float(t.kd),
            acc_min=float(t.acc_min),
            acc_max=float(t.acc_max),
            substeps=int(t.substeps),
            solver=str(t.solver),
            foot_mode=str(a.foot_mode),
            foot_offset=float(a.foot_offset),
            td_enabled=bool(td.enabled),
            late_margin=float(td.late_margin),
            max_delay=int(td.max_delay),
            early_margin=float(td.early_margin),
            early_min_swing=float(td.early_min_swing),
            zero_vertical_velocity=bool(td.zero_vertical_velocity),
            w_stand=float(r.w_stand),
            w_mimic=float(r.w_mimic),
            k_disp=float(r.k_disp),
            k_rot=float(r.k_rot),
            k_ee=float(r.k_ee),
            k_vel=float(r.k_vel),
            max_height=float(term.max_height),
            min_height_ratio=float(term.min_height_ratio),
            min_height_abs=float(term.min_height_abs),
            max_tilt=float(np.radians(term.max_tilt_deg)),
        )
