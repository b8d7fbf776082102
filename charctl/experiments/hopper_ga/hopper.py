"""The hopper legs of Kang (1999): leg geometry, one-leg stance (eq 1-4) and the two-leg cycle (eq 5-7),
vectorised over a population axis N. Frames and angles as in model.py's docstring; units: metres, seconds,
kilograms, radians."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from charctl.experiments.hopper_ga.settings import (
    BAD_GENE,
    EARLY_LIFTOFF,
    FOOT_GROUND,
    HIP_GROUND,
    HIP_RANGE,
    KNEE_LIMIT,
    NO_LIFTOFF,
    NO_PERIODIC,
    SWING_KNEE,
    T_NOT_REAL,
    T_RANGE,
    Params,
    Settings,
)


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
    lift, x_lo, y_lo, vy_lo = _lift_off(st, s)
    T, t_code = _checked_flight_time(y_lo, vy_lo, p, s)
    code |= t_code
    n_f = np.maximum(1, np.rint(T / s.h).astype(int))  # flight frames; step h_f = T / n_f ~ h
    h_f = T / n_f
    end = lift + n_f
    kk, in_stance, mask, tau, t, dt = _frame_grid(lift, end, n_f, h_f, s.h)
    x, y, x_st, y_st = _hip_path(st, kk, lift, in_stance, tau, x_lo, y_lo, vy_lo, xdot, s.g)
    theta_c, theta_l = _leg_angles(p, a, b, x_st, y_st, lift, in_stance, tau, T)
    d, leg_code = _leg_validity(theta_c, theta_l, y, mask, a, b, bend_max, s)
    code |= leg_code
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


def _lift_off(st: Stance, s: Settings) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Lift-off frame (>= 2, placeholders keep invalid rows finite), HIP x and y there (m) and the
    last stance vertical speed (m/s, backward difference)."""
    lift = np.where(st.lift >= 2, st.lift, 2)  # placeholders keep invalid rows finite
    lift = np.minimum(lift, st.x.shape[1] - 1)
    rows = np.arange(len(lift))
    y_lo, y_lo_prev, x_lo = st.y[rows, lift], st.y[rows, lift - 1], st.x[rows, lift]
    vy_lo = (y_lo - y_lo_prev) / s.h  # backward difference: the last stance speed
    return lift, x_lo, y_lo, vy_lo


def _checked_flight_time(y_lo: np.ndarray, vy_lo: np.ndarray, p: Params, s: Settings) -> tuple[np.ndarray, np.ndarray]:
    """Flight time T (s) to touchdown at the swapped pose's HIP height, and its invalidity bits;
    rows without a real T in (0, max_flight_s] get T = h."""
    T = flight_time(y_lo, vy_lo, p.l * np.cos(p.theta0), s.g)
    code = np.where(np.isnan(T), T_NOT_REAL, 0)
    code |= np.where(~np.isnan(T) & ~((T > 0) & (T <= s.max_flight_s)), T_RANGE, 0)
    T = np.where((T > 0) & (T <= s.max_flight_s), T, s.h)
    return T, code


def _frame_grid(
    lift: np.ndarray, end: np.ndarray, n_f: np.ndarray, h_f: np.ndarray, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The common (N, K) frame grid: frame index kk (1, K), stance and cycle masks, time since
    lift-off tau (s), time since touchdown t (s) and its steps dt (padding frames get h, never 0)."""
    K = int(end.max()) + 1
    kk = np.arange(K)[None, :]
    in_stance = kk <= lift[:, None]
    mask = kk <= end[:, None]
    tau = np.clip(kk - lift[:, None], 0, n_f[:, None]) * h_f[:, None]  # time since lift-off
    t = np.where(in_stance, kk * h, lift[:, None] * h + tau)
    dt = np.where(mask, np.diff(t, axis=1, prepend=t[:, :1] - h), h)  # padding frames get h (never 0)
    return kk, in_stance, mask, tau, t, dt


def _hip_path(st: Stance, kk, lift, in_stance, tau, x_lo, y_lo, vy_lo, xdot, g: float) -> tuple[np.ndarray, ...]:
    """HIP x, y (N, K; m, idle-foot frame): stance samples up to lift-off, then the ballistic flight of
    eq 3; also the stance samples held at lift-off (x_st, y_st)."""
    idx = np.minimum(kk, lift[:, None])
    x_st = np.take_along_axis(st.x, idx, axis=1)
    y_st = np.take_along_axis(st.y, idx, axis=1)
    x = np.where(in_stance, x_st, x_lo[:, None] + xdot[:, None] * tau)
    y = np.where(in_stance, y_st, y_lo[:, None] + vy_lo[:, None] * tau + 0.5 * g * tau * tau)
    return x, y, x_st, y_st


def _leg_angles(p: Params, a, b, x_st, y_st, lift, in_stance, tau, T) -> tuple[np.ndarray, np.ndarray]:
    """theta_c and theta_l (N, K, 2; rad; leg 0 idle, 1 active) over the cycle: the idle leg follows the
    HIP in stance, the active leg the idle leg's sweep; in flight eq 5 with B_l = t/T and B_c of eq 6."""
    rows = np.arange(len(lift))
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
    return theta_c, theta_l


def _leg_validity(theta_c, theta_l, y, mask, a, b, bend_max, s: Settings) -> tuple[np.ndarray, np.ndarray]:
    """Hip-foot distances d (N, K, 2; m) and the invalidity bits of the legs over the cycle frames
    (a foot below ground, the active knee out of [0, bend_max], a hip angle beyond +-pi/2)."""
    d = d_from_bend(theta_l, a[:, None, None], b[:, None, None])
    foot_y = y[..., None] - d * np.cos(theta_c)
    m3 = mask[..., None]
    code = np.where(np.any(m3 & ~(foot_y >= -s.ground_tol), axis=(1, 2)), FOOT_GROUND, 0)
    bad_bend = ~((theta_l[..., 1] >= -1e-9) & (theta_l[..., 1] <= bend_max[:, None] + 1e-9))
    code |= np.where(np.any(mask & bad_bend, axis=1), SWING_KNEE, 0)
    code |= np.where(np.any(m3 & ~(np.abs(theta_c) <= np.pi / 2), axis=(1, 2)), HIP_RANGE, 0)
    return d, code
