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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from charctl.experiments.hopper_ga.character import Body, body_from_config, upper_fk, upper_segment_com

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


# ---------------------------------------------------------------------------- leg geometry
def leg_lengths(l: np.ndarray, s: Settings) -> tuple[np.ndarray, np.ndarray]:
    """Thigh a and shank b (m), a + b = l."""
    return s.thigh_fraction * l, (1.0 - s.thigh_fraction) * l


def d_from_bend(theta_l: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hip-foot distance for a hip-side angle theta_l (law of cosines, knee in front)."""
    return a * np.cos(theta_l) + np.sqrt(np.maximum(b * b - (a * np.sin(theta_l)) ** 2, 0.0))


def bend_from_d(d: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """theta_l for a hip-foot distance d (the knee joint keeps |HIP - FOOT| = d)."""
    return np.arccos(np.clip((a * a + d * d - b * b) / (2.0 * a * d), -1.0, 1.0))


def min_leg_distance(a: np.ndarray, b: np.ndarray, s: Settings) -> np.ndarray:
    """Shortest hip-foot distance the knee's flexion limit allows."""
    return np.sqrt(a * a + b * b + 2.0 * a * b * np.cos(s.knee_max_flexion))


# ---------------------------------------------------------------------------- one-leg hopper (eq 1-4)
@dataclass
class Stance:
    x: np.ndarray  # (N, K+1) HIP x relative to the stance foot, m
    y: np.ndarray  # (N, K+1) HIP height, m
    lift: np.ndarray  # (N,) frame index of lift-off (first frame with d >= l), -1 if none
    code: np.ndarray  # (N,) invalidity bits


def integrate_stance(l, kappa, theta0, m, xdot, h: float, g: float, vy0, max_steps: int, d_min) -> Stance:
    """Stance of the one-leg hopper, foot at the origin (eq 1-2).

    x_t = x_0 + x_dot t;  y_t = g h^2 + kappa (l - d) h^2 cos(theta) / m + 2 y_{t-h} - y_{t-2h}
    (Stormer-Verlet: d and theta are taken at t-h, where the acceleration acts). The HIP starts
    at eq 1 with vertical speed vy0; stance lasts while d < l. Arguments are (N,) arrays
    (or scalars); failures (HIP below ground, knee over-folded, no lift-off) set `code` bits.
    """
    l, kappa, theta0, m, xdot, vy0, d_min = np.broadcast_arrays(
        *(np.asarray(v, dtype=float) for v in (l, kappa, theta0, m, xdot, vy0, d_min))
    )
    N = l.shape[0]
    x0, y0 = -l * np.sin(theta0), l * np.cos(theta0)
    xs = np.empty((N, max_steps + 1))
    ys = np.empty((N, max_steps + 1))
    xs[:, 0], ys[:, 0] = x0, y0
    y_prev, y_cur = y0 - vy0 * h, y0.copy()
    lift = np.full(N, -1)
    code = np.zeros(N, dtype=np.int64)
    active = np.ones(N, dtype=bool)
    k_last = 0
    for k in range(1, max_steps + 1):
        d = np.hypot(xs[:, k - 1], y_cur)
        y_new = g * h * h + kappa * (l - d) * h * h * (y_cur / d) / m + 2.0 * y_cur - y_prev
        x_new = x0 + xdot * (k * h)
        d_new = np.hypot(x_new, y_new)
        ground = active & ~(y_new > 0.0)  # also catches NaN
        folded = active & ~ground & (d_new < d_min)
        lifted = active & ~ground & ~folded & (d_new >= l)
        code |= np.where(ground, HIP_GROUND, 0) | np.where(folded, KNEE_LIMIT, 0)
        lift = np.where(lifted, k, lift)
        y_new = np.where(active, y_new, y_cur)  # finished rows stay frozen
        xs[:, k], ys[:, k] = np.where(active, x_new, xs[:, k - 1]), y_new
        active &= ~(ground | folded | lifted)
        y_prev, y_cur = y_cur, y_new
        k_last = k
        if not active.any():
            break
    code |= np.where(active, NO_LIFTOFF, 0)
    code |= np.where((lift >= 0) & (lift < 2), EARLY_LIFTOFF, 0)
    return Stance(x=xs[:, : k_last + 1], y=ys[:, : k_last + 1], lift=lift, code=code)


def flight_time(y0, vy0, yf, g: float) -> np.ndarray:
    """Exact flight time of eq 4: T = (-vy0 - sqrt(vy0^2 + 2 g c)) / g, c = yf - y0.
    NaN where the root is not real (the HIP never comes back down to yf)."""
    c = np.asarray(yf, dtype=float) - np.asarray(y0, dtype=float)
    disc = np.asarray(vy0, dtype=float) ** 2 + 2.0 * g * c
    with np.errstate(invalid="ignore"):
        return np.where(disc >= 0.0, (-vy0 - np.sqrt(np.where(disc >= 0.0, disc, 0.0))) / g, np.nan)


def landing_speed_error(vy_td, l, kappa, theta0, m, xdot, s: Settings, d_min) -> np.ndarray:
    """G(v) = (vertical HIP speed at the end of the flight) - v for a cycle touching down with
    vertical speed v (m/s); NaN where the stance or the flight is impossible. A periodic running
    gait has G = 0: the next touchdown repeats this one."""
    st = integrate_stance(l, kappa, theta0, m, xdot, s.h, s.g, vy_td, s.max_stance_steps, d_min)
    rows = np.arange(l.shape[0])
    k = np.clip(st.lift, 1, st.x.shape[1] - 1)
    vy_lo = (st.y[rows, k] - st.y[rows, k - 1]) / s.h
    T = flight_time(st.y[rows, k], vy_lo, l * np.cos(theta0), s.g)
    ok = (st.code == 0) & (T > 0)
    return np.where(ok, vy_lo + s.g * T - vy_td, np.nan)


def periodic_touchdown(l, kappa, theta0, m, xdot, s: Settings, d_min) -> tuple[np.ndarray, np.ndarray]:
    """Touchdown vertical speed v (m/s, <= 0) of the steady running cycle, and a mask of the rows
    that have one: G(v) = landing speed - v = 0, so that the next touchdown repeats this one.

    G is scanned on hopper.periodic_scan speeds in [-max_touchdown_speed, 0] (denser near 0);
    the sign change closest to v = 0 (the gentlest periodic gait) is refined by regula falsi
    (Illinois variant) for hopper.periodic_iterations steps. Rows without a sign change, or that
    do not reach |G| < periodic_tol, have no periodic gait. Each row is solved independently."""
    N = l.shape[0]
    args = (l, kappa, theta0, m, xdot)
    grid = -s.max_touchdown_speed * (np.arange(s.periodic_scan) / (s.periodic_scan - 1)) ** 2  # 0 ... -vmax
    G = np.stack([landing_speed_error(np.full(N, v), *args, s, d_min) for v in grid], 1)  # (N, n)
    # bracket [grid[j+1], grid[j]] with G(grid[j]) < 0 < G(grid[j+1]); first j from v = 0
    change = (G[:, :-1] < 0) & (G[:, 1:] > 0)
    has = change.any(axis=1)
    j = np.argmax(change, axis=1)
    rows = np.arange(N)
    hi_v, hi_g = grid[j], G[rows, j]  # G < 0 side (faster landing than touchdown)
    lo_v, lo_g = grid[j + 1], G[rows, j + 1]  # G > 0 side
    v = np.where(has, hi_v, 0.0)
    g = np.where(has, hi_g, np.nan)
    done = has & (np.abs(g) < s.periodic_tol)
    side = np.zeros(N, dtype=int)
    for _ in range(s.periodic_iterations):
        todo = np.flatnonzero(has & ~done)
        if len(todo) == 0:
            break
        a_v, a_g, b_v, b_g = lo_v[todo], lo_g[todo], hi_v[todo], hi_g[todo]
        v_new = (a_v * b_g - b_v * a_g) / (b_g - a_g)
        g_new = landing_speed_error(v_new, *(x[todo] for x in args), s, d_min[todo])
        bad = np.isnan(g_new)
        has[todo[bad]] = False
        pos = g_new > 0
        # Illinois: halve the stale end's value when the same end is kept twice
        lo_v[todo] = np.where(pos, v_new, a_v)
        lo_g[todo] = np.where(pos, g_new, np.where(side[todo] == -1, a_g / 2, a_g))
        hi_v[todo] = np.where(pos, b_v, v_new)
        hi_g[todo] = np.where(pos, np.where(side[todo] == 1, b_g / 2, b_g), g_new)
        side[todo] = np.where(pos, 1, -1)
        v[todo], g[todo] = v_new, g_new
        done[todo] = ~bad & (np.abs(g_new) < s.periodic_tol)
    return v, has & done


def b_curve(tau, T, alpha) -> np.ndarray:
    """B_c of eq 6: (tau^2 - 2 alpha T tau) / (T^2 (1 - 2 alpha)); 0 at 0, 1 at T, extremum at alpha T."""
    return (tau * tau - 2.0 * alpha * T * tau) / (T * T * (1.0 - 2.0 * alpha))


# ---------------------------------------------------------------------------- two-leg cycle (eq 5-7)
@dataclass
class Cycle:
    """One stance + flight of the two-leg hopper on a common frame grid (N, K). Leg axis: 0 = idle
    (stance) leg, 1 = active leg. x is relative to the idle foot; frames after `end` repeat the last."""

    t: np.ndarray  # (N, K) s since touchdown
    dt: np.ndarray  # (N, K) t[k] - t[k-1] (dt[:, 0] = h)
    mask: np.ndarray  # (N, K) frame belongs to the cycle
    hip: np.ndarray  # (N, K, 2) HIP (x, y)
    theta_c: np.ndarray  # (N, K, 2)
    theta_l: np.ndarray  # (N, K, 2)
    target_x: np.ndarray  # (N, K) eq 7 target COM, x (m, idle-foot frame)
    target_w: np.ndarray  # (N, K) weight of the active foot's z in the eq 7 target (0 in stance, t/T in flight)
    lift: np.ndarray  # (N,) lift-off frame
    end: np.ndarray  # (N,) last frame (touchdown of the active leg)
    T: np.ndarray  # (N,) flight time
    xdot: np.ndarray  # (N,)
    code: np.ndarray  # (N,) invalidity bits

    def take(self, rows: np.ndarray) -> Cycle:
        """The cycles of `rows`, cropped to their own longest cycle."""
        K = int(self.end[rows].max()) + 1 if len(rows) else 1
        return Cycle(**{k: (v[rows, :K] if v.ndim >= 2 else v[rows]) for k, v in self.__dict__.items()})


def leg_cycle(p: Params, s: Settings, xdot: np.ndarray | float | None = None) -> Cycle:
    """Simulate one running cycle of the two-leg hopper for every row of `p`."""
    N = p.l.shape[0]
    xdot = np.broadcast_to(np.asarray(s.speed if xdot is None else xdot, dtype=float), (N,)).copy()
    a, b = leg_lengths(p.l, s)
    d_min = min_leg_distance(a, b, s)
    bend_max = bend_from_d(d_min, a, b)
    if s.periodic:
        vy_td, periodic = periodic_touchdown(p.l, p.kappa, p.theta0, p.m, xdot, s, d_min)
    else:
        vy_td, periodic = np.full(N, s.touchdown_vy), np.ones(N, dtype=bool)
    st = integrate_stance(p.l, p.kappa, p.theta0, p.m, xdot, s.h, s.g, vy_td, s.max_stance_steps, d_min)
    code = st.code | np.where(p.bad, BAD_GENE, 0) | np.where(periodic, 0, NO_PERIODIC)
    lift = np.where(st.lift >= 2, st.lift, 2)  # placeholders keep invalid rows finite
    lift = np.minimum(lift, st.x.shape[1] - 1)
    rows = np.arange(N)
    y_lo, y_lo_prev, x_lo = st.y[rows, lift], st.y[rows, lift - 1], st.x[rows, lift]
    vy_lo = (y_lo - y_lo_prev) / s.h  # backward difference: the last stance speed
    T = flight_time(y_lo, vy_lo, p.l * np.cos(p.theta0), s.g)
    code |= np.where(np.isnan(T), T_NOT_REAL, 0)
    code |= np.where(~np.isnan(T) & ~((T > 0) & (T <= s.max_flight_s)), T_RANGE, 0)
    T = np.where((T > 0) & (T <= s.max_flight_s), T, s.h)
    n_f = np.maximum(1, np.rint(T / s.h).astype(int))  # flight frames; step h_f = T / n_f ~ h
    h_f = T / n_f
    end = lift + n_f
    K = int(end.max()) + 1
    kk = np.arange(K)[None, :]
    in_stance = kk <= lift[:, None]
    mask = kk <= end[:, None]
    tau = np.clip(kk - lift[:, None], 0, n_f[:, None]) * h_f[:, None]  # time since lift-off
    t = np.where(in_stance, kk * s.h, lift[:, None] * s.h + tau)
    dt = np.where(mask, np.diff(t, axis=1, prepend=t[:, :1] - s.h), s.h)  # padding frames get h (never 0)
    # HIP: stance samples up to lift-off, then the ballistic flight of eq 3
    idx = np.minimum(kk, lift[:, None])
    x_st = np.take_along_axis(st.x, idx, axis=1)
    y_st = np.take_along_axis(st.y, idx, axis=1)
    x = np.where(in_stance, x_st, x_lo[:, None] + xdot[:, None] * tau)
    y = np.where(in_stance, y_st, y_lo[:, None] + vy_lo[:, None] * tau + 0.5 * s.g * tau * tau)
    # idle leg in stance: the hopper's leg (knee keeps |HIP - FOOT| = d <= l)
    th_c_i = np.arctan2(-x_st, y_st)
    th_l_i = bend_from_d(np.minimum(np.hypot(x_st, y_st), p.l[:, None]), a[:, None], b[:, None])
    # active leg in stance: driven by the idle leg's sweep (the "scaled HIP motion" of 3.2.1)
    sweep = p.theta0[:, None] - th_c_i
    th_c_a = p.swing_angle[:, None] + p.swing_gain[:, None] * sweep
    th_l_a = p.swing_bend[:, None] + p.bend_gain[:, None] * sweep
    # flight: eq 5 with B_l = t/T and B_c of eq 6, towards the swapped touchdown pose
    lo = lambda v: v[rows, lift][:, None]  # noqa: E731  value at lift-off
    B_l = tau / T[:, None]
    B_c = b_curve(tau, T[:, None], p.alpha[:, None])
    idle_c = lo(th_c_i) + (p.swing_angle[:, None] - lo(th_c_i)) * B_c
    idle_l = lo(th_l_i) + (p.swing_bend[:, None] - lo(th_l_i)) * B_l
    act_c = lo(th_c_a) + (p.theta0[:, None] - lo(th_c_a)) * B_c
    act_l = lo(th_l_a) * (1.0 - B_l)
    theta_c = np.stack([np.where(in_stance, th_c_i, idle_c), np.where(in_stance, th_c_a, act_c)], -1)
    theta_l = np.stack([np.where(in_stance, th_l_i, idle_l), np.where(in_stance, th_l_a, act_l)], -1)
    # validity of the legs over the cycle frames
    d = d_from_bend(theta_l, a[:, None, None], b[:, None, None])
    foot_y = y[..., None] - d * np.cos(theta_c)
    m3 = mask[..., None]
    code |= np.where(np.any(m3 & ~(foot_y >= -s.ground_tol), axis=(1, 2)), FOOT_GROUND, 0)
    bad_bend = ~((theta_l[..., 1] >= -1e-9) & (theta_l[..., 1] <= bend_max[:, None] + 1e-9))
    code |= np.where(np.any(mask & bad_bend, axis=1), SWING_KNEE, 0)
    code |= np.where(np.any(m3 & ~(np.abs(theta_c) <= np.pi / 2), axis=(1, 2)), HIP_RANGE, 0)
    # eq 7 target COM (x): the idle foot in stance, idle -> active foot over the flight
    foot_a_x = x + d[..., 1] * np.sin(theta_c[..., 1])
    w = np.where(in_stance, 0.0, tau / T[:, None])
    target_x = w * foot_a_x  # idle foot at x = 0
    hip = np.stack([x, y], -1)
    return Cycle(
        t=t,
        dt=dt,
        mask=mask,
        hip=hip,
        theta_c=theta_c,
        theta_l=theta_l,
        target_x=target_x,
        target_w=w,
        lift=lift,
        end=end,
        T=T,
        xdot=xdot,
        code=code,
    )


# ---------------------------------------------------------------------------- timeline of cycles
@dataclass
class Timeline:
    """Frames of one or more cycles in world coordinates. Leg axis: 0 = right, 1 = left."""

    t: np.ndarray  # (N, K)
    dt: np.ndarray  # (N, K)
    mask: np.ndarray  # (N, K)
    xdot: np.ndarray  # (N, K) HIP speed of the frame's cycle
    hip: np.ndarray  # (N, K, 2) world (x, y)
    theta_c: np.ndarray  # (N, K, 2) right, left
    theta_l: np.ndarray  # (N, K, 2)
    target: np.ndarray  # (N, K, 2) eq 7 target COM (x, z) in the ground plane
    support: np.ndarray  # (N, K) 0 right stance, 1 left stance, -1 flight
    lift: np.ndarray  # (N,) first lift-off frame
    end: np.ndarray  # (N,) last frame
    l: np.ndarray  # (N,)


def single_cycle_timeline(c: Cycle, p: Params, s: Settings) -> Timeline:
    """The GA's evaluation window: one cycle, right leg idle, starting at the right foot x = 0."""
    w = s.body.hip_half_width
    tz = w + (-w - w) * c.target_w  # right foot (+w) -> left foot (-w)
    support = np.where(c.target_w > 0, -1, 0)
    return Timeline(
        t=c.t,
        dt=c.dt,
        mask=c.mask,
        xdot=np.broadcast_to(c.xdot[:, None], c.t.shape),
        hip=c.hip,
        theta_c=c.theta_c,
        theta_l=c.theta_l,
        target=np.stack([c.target_x, tz], -1),
        support=support,
        lift=c.lift,
        end=c.end,
        l=p.l,
    )


def repeat_cycles(cycles: list[Cycle], p: Params, s: Settings, first_right: bool = True) -> Timeline:
    """Chain cycles (N = 1 each) into a run, alternating the stance leg; the touchdown frame of
    one cycle is the first frame of the next. Used for export, the COM path and the limp test."""
    w = s.body.hip_half_width
    t_all, dt_all, xd_all, hip_all, tc_all, tl_all, tar_all, sup_all = [], [], [], [], [], [], [], []
    x_off, t_off = 0.0, 0.0
    for i, c in enumerate(cycles):
        if c.t.shape[0] != 1:
            raise ValueError("repeat_cycles takes single-individual cycles")
        n = int(c.end[0]) + 1
        start = 0 if i == 0 else 1
        right = (i % 2 == 0) == first_right
        z_i = w if right else -w
        sl = slice(start, n)
        order = [0, 1] if right else [1, 0]  # leg axis: idle/active -> right/left
        t_all.append(c.t[0, sl] + t_off)
        dt_all.append(c.dt[0, sl])
        xd_all.append(np.full(n - start, c.xdot[0]))
        hip_all.append(c.hip[0, sl] + [x_off, 0.0])
        tc_all.append(c.theta_c[0, sl][:, order])
        tl_all.append(c.theta_l[0, sl][:, order])
        tz = z_i + (-z_i - z_i) * c.target_w[0, sl]
        tar_all.append(np.stack([c.target_x[0, sl] + x_off, tz], -1))
        sup_all.append(np.where(c.target_w[0, sl] > 0, -1, 0 if right else 1))
        a_land = c.hip[0, n - 1, 0] + p.l[0] * np.sin(p.theta0[0])  # landing foot x (next cycle's origin)
        x_off += a_land
        t_off += c.t[0, n - 1]
    cat = lambda v: np.concatenate(v)[None]  # noqa: E731
    K = sum(len(v) for v in t_all)
    return Timeline(
        t=cat(t_all),
        dt=cat(dt_all),
        mask=np.ones((1, K), dtype=bool),
        xdot=cat(xd_all),
        hip=cat(hip_all),
        theta_c=cat(tc_all),
        theta_l=cat(tl_all),
        target=cat(tar_all),
        support=cat(sup_all),
        lift=cycles[0].lift.copy(),
        end=np.array([K - 1]),
        l=p.l.copy(),
    )


# ---------------------------------------------------------------------------- geometry of the whole body
@dataclass
class LegPoints:
    hip: np.ndarray  # (N, K, 2, 3) hip joints (right, left)
    knee: np.ndarray
    foot: np.ndarray
    thigh_dir: np.ndarray
    shank_dir: np.ndarray


def leg_points(tl: Timeline, s: Settings) -> LegPoints:
    """3-D hip, knee and foot positions of both legs (world, m)."""
    a, b = leg_lengths(tl.l, s)
    a4, b4 = a[:, None, None, None], b[:, None, None, None]
    w = s.body.hip_half_width
    N, K = tl.mask.shape
    hip = np.zeros((N, K, 2, 3))
    hip[..., 0] = tl.hip[..., 0, None]
    hip[..., 1] = tl.hip[..., 1, None]
    hip[..., 2] = [w, -w]
    ang = tl.theta_c + tl.theta_l
    thigh = np.stack([np.sin(ang), -np.cos(ang), np.zeros_like(ang)], -1)
    d = d_from_bend(tl.theta_l, a[:, None, None], b[:, None, None])[..., None]
    foot = hip + d * np.stack([np.sin(tl.theta_c), -np.cos(tl.theta_c), np.zeros_like(ang)], -1)
    knee = hip + a4 * thigh
    shank = (foot - knee) / b4
    return LegPoints(hip=hip, knee=knee, foot=foot, thigh_dir=thigh, shank_dir=shank)


def lower_mass_moment(tl: Timeline, legs: LegPoints, s: Settings) -> np.ndarray:
    """(N, K, 3) sum of M_i L_i (eq 8) over the pelvis and both legs."""
    body = s.body
    a, b = leg_lengths(tl.l, s)
    thigh_com = legs.hip + (body.thigh_com * a)[:, None, None, None] * legs.thigh_dir
    shank_com = legs.knee + (body.shank_com * b)[:, None, None, None] * legs.shank_dir
    pelvis = np.concatenate([tl.hip, np.zeros(tl.hip.shape[:-1] + (1,))], -1)
    return (
        body.pelvis_mass * pelvis
        + body.thigh_mass * (thigh_com[..., 0, :] + thigh_com[..., 1, :])
        + body.shank_mass * (shank_com[..., 0, :] + shank_com[..., 1, :])
    )


# ---------------------------------------------------------------------------- balance (eq 7-11)
@dataclass
class Balance:
    angles: np.ndarray  # (N, K, D) balance DOF angles (rad), order of body.dof_names
    com: np.ndarray  # (N, K, 3) whole-body COM (eq 8)
    code: np.ndarray  # (N,)


def dof_to_joint_angles(z: np.ndarray, body: Body) -> np.ndarray:
    """(..., D) DOF angles -> (..., J, 2) (phi_z, phi_x) per upper joint."""
    out = np.zeros(z.shape[:-1] + (len(body.names), 2))
    out[..., body.dof_joint, body.dof_axis] = z
    return out


def run_balance(tl: Timeline, eta: np.ndarray, s: Settings) -> Balance:
    """Trunk response of eq 9-11, integrated with eq 10 over the timeline (all rows at once).

    delta = CM_tar - CM_cur in the ground plane (x, z). Per DOF, zd = eta delta_x h / x_dot
    (sagittal, z axis) and xd = eta (-delta_z) h / x_dot (lateral, x axis) in the paper's
    convention; in the charctl right-handed frame (z = right) leaning forward is a negative
    rotation about +z and leaning right a positive rotation about +x, so the applied responses
    are -eta delta_x h / x_dot about z and +eta delta_z h / x_dot about x: both move the COM
    towards the target, as the paper intends. The body starts upright at rest.
    """
    body = s.body
    N, K = tl.mask.shape
    D = body.num_dofs
    legs = leg_points(tl, s)
    lower = lower_mass_moment(tl, legs, s)
    pelvis = np.concatenate([tl.hip, np.zeros((N, K, 1))], -1)
    sagittal = body.dof_axis == 0
    Z = np.zeros((N, K, D))
    com = np.empty((N, K, 3))

    def com_of(k: int, z: np.ndarray) -> np.ndarray:
        pos, rot = upper_fk(body, pelvis[:, k], dof_to_joint_angles(z, body))
        seg = upper_segment_com(body, pos, rot)
        upper = (body.seg_mass[None, :, None] * seg).sum(axis=1) if len(body.names) else 0.0
        return (lower[:, k] + upper) / body.mass

    z1 = np.zeros((N, D))
    z2 = np.zeros((N, D))
    z3 = np.zeros((N, D))
    com[:, 0] = com_of(0, z1)
    h_prev = np.full(N, s.h)
    for k in range(1, K):
        h_k = tl.dt[:, k]
        delta = tl.target[:, k - 1] - com[:, k - 1][:, [0, 2]]  # eq 9, (x, z)
        err = np.where(sagittal, -delta[:, :1], delta[:, 1:])  # eq 11 in the charctl frame
        resp = eta * err * (h_k / tl.xdot[:, k - 1])[:, None]
        v1 = (z1 - z2) / tl.dt[:, k - 1, None]
        v2 = (z2 - z3) / h_prev[:, None]
        acc = (v1 - v2) / tl.dt[:, k - 1, None]
        z_new = z1 + ((v1 + acc * h_k[:, None]) * h_k[:, None] + resp) / 2.0  # eq 10
        z_new = np.where(tl.mask[:, k, None], z_new, z1)
        Z[:, k] = z_new
        com[:, k] = com_of(k, z_new)
        h_prev = tl.dt[:, k - 1]
        z3, z2, z1 = z2, z1, z_new
    over = np.any(tl.mask[..., None] & ~(np.abs(Z) <= s.angle_limit), axis=(1, 2))
    return Balance(angles=Z, com=com, code=np.where(over, BALANCE_LIMIT, 0))


# ---------------------------------------------------------------------------- joint angles
def leg_joint_angles(tl: Timeline, legs: LegPoints) -> np.ndarray:
    """(N, K, 4) sagittal rotations (rad, about +z) of right hip, right knee, left hip, left knee.
    Hip = thigh angle from straight down (forward positive); knee = shank minus thigh (<= 0: flexion)."""
    thigh = tl.theta_c + tl.theta_l
    shank = np.arctan2(legs.shank_dir[..., 0], -legs.shank_dir[..., 1])
    knee = shank - thigh
    return np.stack([thigh[..., 0], knee[..., 0], thigh[..., 1], knee[..., 1]], -1)


def dof_inertia(l: np.ndarray, s: Settings) -> np.ndarray:
    """(N, 4 + D) rotational inertia I_i (kg m^2) of every joint DOF of eq 12, rest pose, rods."""
    body = s.body
    a, b = leg_lengths(l, s)
    mt, ms = body.thigh_mass, body.shank_mass
    I_hip = mt * (a * a / 12 + (body.thigh_com * a) ** 2) + ms * (b * b / 12 + (a + body.shank_com * b) ** 2)
    I_knee = ms * (b * b / 12 + (body.shank_com * b) ** 2)
    legs = np.stack([I_hip, I_knee, I_hip, I_knee], -1)
    return np.concatenate([legs, np.broadcast_to(body.dof_inertia, (l.shape[0], body.num_dofs))], -1)


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
    return _finish(ps, single_cycle_timeline(cs, ps, s), cs.code, s), p, c.code, rows


def _finish(p: Params, tl: Timeline, code: np.ndarray, s: Settings) -> Rollout:
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
