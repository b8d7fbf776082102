"""The running model of Kang (1999): planar two-leg spring hopper + upper-body balance.

Everything is vectorised over a population axis N (rows = individuals); Python loops run over
time steps and hierarchy levels only. Units: metres, seconds, kilograms, radians.

Frames. The hopper is planar in (x, y): x forward, y up (eq 1-6). The character lives in the
charctl world (y up, running along +x, right side +z); each leg moves in its own sagittal plane
z = +-hip_half_width. Leg angles:
    theta_c  angle of HIP - FOOT with the +y axis; HIP - FOOT = d (-sin theta_c, cos theta_c),
             so theta_c > 0 means the foot is ahead of the hip (eq 1: touchdown at theta0 > 0);
    theta_l  angle between JOINT - HIP and FOOT - HIP (the knee sits in front of the hip-foot
             line); with thigh a and shank b, a + b = l, the hip-foot distance is
             d = a cos theta_l + sqrt(b^2 - a^2 sin^2 theta_l)  (the knee keeps |HIP-FOOT| = d).

One cycle = stance on the idle (right) leg from touchdown until d >= l, then a flight of the
exact ballistic time T (eq 4) while both legs interpolate (eq 5-6) towards the swapped start
pose; the cycle ends with the active (left) leg touching down at theta0.

The model's parts: `settings.py` (settings, genome, invalidity codes), `hopper.py` (leg geometry, stance
and the two-leg cycle, eq 1-7), `body.py` (timeline, leg points, balance and joint angles, eq 7-11); this
module holds the fitness (eq 12-14) and `evaluate_genomes`, the entry point of the GA.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from charctl.experiments.hopper_ga.body import (
    Balance,
    LegPoints,
    Timeline,
    dof_inertia,
    leg_joint_angles,
    leg_points,
    run_balance,
    single_cycle_timeline,
)
from charctl.experiments.hopper_ga.hopper import leg_cycle
from charctl.experiments.hopper_ga.settings import BAD_GENE, Params, Settings, decode


# ---------------------------------------------------------------------------- fitness (eq 12-14)
def ordered_sum(v: np.ndarray, axis: int = -1) -> np.ndarray:
    """Left-to-right sum: trailing zero padding never changes a row's result (batch-size invariant)."""
    return np.cumsum(v, axis=axis).take(-1, axis=axis)


def smoothness(theta: np.ndarray, dt: np.ndarray, lift: np.ndarray, s: Settings) -> np.ndarray:
    """gamma of eq 12 at the stance -> flight switch, summed over joint DOFs.

    theta_dot_f: first flight speed (forward difference from the lift-off frame);
    theta_dot_s, theta_ddot_s: last stance speed and acceleration (backward differences);
    predicted speed = theta_dot_s + theta_ddot_s * h (the paper writes theta_dot_s + theta_ddot_s).
    max/min of the two speeds is taken on magnitudes softened by omega_floor w,
    sign * (max|.| + w) / (min|.| + w) with sign = -1 when the speeds point opposite ways (as the
    paper's max/min of two signed speeds is negative then): 1 iff the speeds are equal, the paper's
    ratio when both are >> w, and no division by zero when one speed vanishes.
    """
    rows = np.arange(theta.shape[0])
    k = lift
    th = [theta[rows, k + i] for i in (-2, -1, 0, 1)]
    v_s = (th[2] - th[1]) / dt[rows, k, None]
    v_s1 = (th[1] - th[0]) / dt[rows, k - 1, None]
    a_s = (v_s - v_s1) / dt[rows, k, None]
    v_f = (th[3] - th[2]) / dt[rows, k + 1, None]
    pred = v_s + a_s * (s.h if s.predict_with_h else 1.0)
    w = s.omega_floor
    big, small = np.maximum(np.abs(v_f), np.abs(pred)), np.minimum(np.abs(v_f), np.abs(pred))
    ratio = np.where(v_f * pred >= 0, 1.0, -1.0) * (big + w) / (small + w)
    return ordered_sum((ratio - 1.0) ** 2)


def energy_rate(theta: np.ndarray, tl: Timeline, com: np.ndarray, inertia: np.ndarray, s: Settings) -> np.ndarray:
    """E_r of eq 12: integral over the window of (sum_i I_i |theta_ddot_i|^2 + tau) dt divided by
    the distance travelled, in units of fitness.energy_scale. tau = gravity torque M |g| |CM_cur -
    CM_tar| (horizontal lever arm of the weight about the target support point)."""
    N, K = tl.mask.shape
    dt = tl.dt
    v = np.diff(theta, axis=1) / dt[:, 1:, None]  # speed on [k-1, k], k = 1..K-1
    w_mid = 0.5 * (dt[:, 1:-1] + dt[:, 2:])  # quadrature weight of interior frame k = 1..K-2
    acc = (v[:, 1:] - v[:, :-1]) / w_mid[..., None]  # at k = 1..K-2
    lever = np.hypot(com[..., 0] - tl.target[..., 0], com[..., 2] - tl.target[..., 1])
    tau = s.body.mass * abs(s.g) * lever
    power = ordered_sum(inertia[:, None, :] * acc * acc) + tau[:, 1:-1]
    inside = tl.mask[:, 2:]  # frame k+1 exists -> acceleration at k is defined
    total = ordered_sum(np.where(inside, power * w_mid, 0.0))
    rows = np.arange(N)
    dist = tl.hip[rows, tl.end, 0] - tl.hip[:, 0, 0]
    return total / np.maximum(dist, 1e-9) / s.energy_scale


def eval_score(gamma, energy) -> np.ndarray:
    """eq 13/14: eval = 1 - 1/(2(1+gamma)) - 1/(2(1+E)); 0 at (0, 0), -> 1 as both grow."""
    return 1.0 - 0.5 / (1.0 + np.asarray(gamma)) - 0.5 / (1.0 + np.asarray(energy))


def energy_target_error(E_r, beta: float) -> np.ndarray:
    """E of eq 14: (beta / (1 - beta) - E_r)^2."""
    return (beta / (1.0 - beta) - np.asarray(E_r)) ** 2


# ---------------------------------------------------------------------------- evaluation
@dataclass
class Rollout:
    """Everything computed for a batch of genomes over one window (cycle or run)."""

    params: Params
    timeline: Timeline
    legs: LegPoints
    balance: Balance
    theta: np.ndarray  # (N, K, 4 + D) all joint DOF angles
    code: np.ndarray


def simulate(genomes: np.ndarray, s: Settings) -> tuple[Rollout | None, Params, np.ndarray, np.ndarray]:
    """One evaluation cycle (stance start -> end of flight) for every genome row.

    Returns (rollout of the rows whose legs are physically possible, or None; the params of all
    rows; the invalidity code of all rows; the indices of the rolled-out rows). The balance
    model (the expensive part) runs only on rows whose legs are valid."""
    p = decode(genomes, s)
    c = leg_cycle(p, s)
    rows = np.flatnonzero(c.code == 0)
    if len(rows) == 0:
        return None, p, c.code, rows
    ps, cs = p.take(rows), c.take(rows)
    return finish_rollout(ps, single_cycle_timeline(cs, ps, s), cs.code, s), p, c.code, rows


def finish_rollout(p: Params, tl: Timeline, code: np.ndarray, s: Settings) -> Rollout:
    bal = run_balance(tl, p.eta, s)
    legs = leg_points(tl, s)
    theta = np.concatenate([leg_joint_angles(tl, legs), bal.angles], -1)
    return Rollout(params=p, timeline=tl, legs=legs, balance=bal, theta=theta, code=code | bal.code)


def evaluate_genomes(genomes: np.ndarray, s: Settings) -> dict[str, np.ndarray]:
    """Fitness of each genome row (eq 12-14): eval (inf for physically impossible individuals),
    gamma, E_r, E, plus the gait numbers. Row results never depend on the other rows."""
    with np.errstate(all="ignore"):
        r, p, code, rows = simulate(genomes, s)
        N = p.l.shape[0]
        out = {k: np.full(N, np.nan) for k in ("gamma", "E_r", "E", "stance_time", "flight_time", "step_length")}
        code = code.copy()
        if r is not None:
            tl = r.timeline
            gamma = smoothness(r.theta, tl.dt, tl.lift, s)
            E_r = energy_rate(r.theta, tl, r.balance.com, dof_inertia(r.params.l, s), s)
            sub = np.arange(len(rows))
            stance_time = tl.t[sub, tl.lift]
            values = {
                "gamma": gamma,
                "E_r": E_r,
                "E": energy_target_error(E_r, s.beta),
                "stance_time": stance_time,
                "flight_time": tl.t[sub, tl.end] - stance_time,
                "step_length": tl.hip[sub, tl.end, 0] - tl.hip[:, 0, 0],  # HIP travel = foot-to-foot distance
            }
            for k, v in values.items():
                out[k][rows] = v
            code[rows] = r.code
        score = eval_score(out["gamma"], out["E"])
        code |= np.where(np.isfinite(score) | (code != 0), 0, BAD_GENE)
        valid = code == 0
    return {"fitness": np.where(valid, score, np.inf), "valid": valid, "code": code, **out}
