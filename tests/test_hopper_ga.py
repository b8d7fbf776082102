"""hopper-ga model checks against hand-derived or independent values (fast, no GA runs).

Flight time vs an independent ballistic root find, spring-mass energy in stance, eq 6 and eq 13/14
identities, the knee geometry, the balance sign conventions, invalid genomes, batch invariance
of the vectorised evaluation, and the exports (BVH read back by charctl's own reader, MuJoCo's
kinematics of the render model) against the model's forward kinematics.
"""

from __future__ import annotations

import numpy as np
import pytest
from omegaconf import OmegaConf
from scipy.optimize import brentq

from charctl.experiments.hopper_ga import body as HB
from charctl.experiments.hopper_ga import hopper as HH
from charctl.experiments.hopper_ga import model as M
from charctl.experiments.hopper_ga import settings as HS
from charctl.experiments.hopper_ga.config import Config

# A valid individual at 5 m/s and one at 2 m/s (found by seeded random search with the default bounds).
GENOME_5 = [
    0.8511,
    11607.1404,
    0.7953,
    63.9895,
    0.8507,
    -1.1667,
    0.9902,
    2.2971,
    -0.3036,
    9.5988,
    5.943,
    5.6482,
    9.4801,
    5.5407,
    5.8794,
    5.674,
    4.4077,
    8.7253,
    7.0736,
]
GENOME_2 = [
    0.7669,
    11951.1486,
    0.7727,
    88.7954,
    0.8559,
    -1.1657,
    1.093,
    1.1511,
    -0.3078,
    5.9613,
    4.9251,
    6.6899,
    8.5358,
    7.3437,
    1.1204,
    8.3205,
    0.5106,
    7.0555,
    1.8755,
]


def settings(**over) -> HS.Settings:
    cfg = OmegaConf.structured(Config)
    for k, v in over.items():
        OmegaConf.update(cfg, k, v)
    return HS.settings_from_config(cfg)


# ---------------------------------------------------------------------------- eq 1-4
def test_flight_time_matches_independent_ballistic_root():
    rng = np.random.default_rng(0)
    y0 = rng.uniform(0.5, 1.2, 200)
    vy0 = rng.uniform(-1.0, 4.0, 200)
    yf = rng.uniform(0.5, 1.2, 200)
    g = -9.81
    T = HH.flight_time(y0, vy0, yf, g)
    for i in range(200):
        f = lambda t: y0[i] + vy0[i] * t + 0.5 * g * t * t - yf[i]  # noqa: E731, B023 (called in this iteration)
        t_apex = max(vy0[i] / -g, 0.0)
        if f(t_apex) < 0:  # never reaches yf on the way down: eq 4 has no real root
            assert np.isnan(T[i])
            continue
        assert T[i] == pytest.approx(brentq(f, t_apex, 10.0), abs=1e-9)
    assert np.isfinite(T).sum() > 100 and np.isnan(T).sum() > 5


def _vertical_energy(h: float, xdot: float = 0.0, theta0: float = 0.0, steps: int | None = None):
    """Stance of eq 2 for a 1-leg hopper; returns t, x, y, and the spring-mass energy terms."""
    l, kappa, m, g = 1.0, 9000.0, 60.0, -9.81
    n = steps or int(round(0.6 / h))
    st = HH.integrate_stance(
        np.array([l]),
        np.array([kappa]),
        np.array([theta0]),
        np.array([m]),
        np.array([xdot]),
        h,
        g,
        np.array([-1.5]),
        n,
        np.array([0.0]),
    )
    k = int(st.lift[0])
    assert k > 10, "the hopper should stay in stance for a while"
    x, y = st.x[0, : k + 1], st.y[0, : k + 1]
    vy = (y[2:] - y[:-2]) / (2 * h)  # central difference (the Verlet velocity)
    xm, ym = x[1:-1], y[1:-1]
    d = np.hypot(xm, ym)
    E = 0.5 * m * vy**2 - m * g * ym + 0.5 * kappa * (l - d) ** 2
    return h * np.arange(1, k), xm, ym, d, E, (l, kappa, m)


@pytest.mark.parametrize("h", [2e-3, 1e-3])
def test_vertical_stance_conserves_spring_mass_energy(h):
    _, _, _, _, E, _ = _vertical_energy(h)
    assert np.ptp(E) / abs(E.mean()) < 40 * h * h  # Stormer-Verlet: bounded O(h^2) energy error


def test_stance_energy_error_shrinks_like_h_squared():
    e1 = np.ptp(_vertical_energy(2e-3)[4])
    e2 = np.ptp(_vertical_energy(1e-3)[4])
    assert 3.0 < e1 / e2 < 5.0


def test_running_stance_energy_balances_the_driver_work():
    """x_dot > 0: x is prescribed, so the vertical spring-mass energy changes only by the work of
    the horizontal driver, W = int dV/dx x_dot dt with V = kappa (l - d)^2 / 2."""
    h = 5e-4
    t, x, y, d, E, (l, kappa, m) = _vertical_energy(h, xdot=3.0, theta0=0.3)
    dVdx = -kappa * (l - d) * x / d
    W = np.concatenate([[0.0], np.cumsum(0.5 * (dVdx[1:] + dVdx[:-1]) * 3.0 * h)])
    assert np.ptp(W) > 50.0  # the driver does real work here ...
    assert np.max(np.abs(E - E[0] - W)) < 0.01 * np.ptp(W)  # ... and it accounts for the energy change


# ---------------------------------------------------------------------------- eq 5-6, knee
def test_b_curve_endpoints_and_extremum():
    T = 0.37
    for alpha in (0.6, 0.9, 1.0):
        tau = np.linspace(0, T, 20001)
        B = HH.b_curve(tau, T, alpha)
        assert B[0] == pytest.approx(0.0) and B[-1] == pytest.approx(1.0)
        if alpha < 1.0:
            assert tau[np.argmax(B)] == pytest.approx(alpha * T, abs=T / 10000)


def test_knee_keeps_hip_foot_distance_and_leg_length():
    s = settings(speed=5.0)
    p = HS.decode(np.array([GENOME_5]), s)
    c = HH.leg_cycle(p, s)
    assert c.code[0] == 0
    tl = HB.single_cycle_timeline(c, p, s)
    legs = HB.leg_points(tl, s)
    l = p.l[0]
    a, b = HH.leg_lengths(p.l, s)
    thigh = np.linalg.norm(legs.knee - legs.hip, axis=-1)
    shank = np.linalg.norm(legs.foot - legs.knee, axis=-1)
    np.testing.assert_allclose(thigh + shank, l, atol=1e-9)  # |HIP-JOINT| + |JOINT-FOOT| = l
    n = int(c.lift[0])
    hip_foot = np.linalg.norm(legs.foot[0, :n, 0] - legs.hip[0, :n, 0], axis=-1)
    hopper_d = np.hypot(tl.hip[0, :n, 0], tl.hip[0, :n, 1])  # stance: the one-leg hopper's d
    np.testing.assert_allclose(hip_foot, np.minimum(hopper_d, l), atol=1e-9)
    np.testing.assert_allclose(legs.foot[0, :n, 0, 1], 0.0, atol=1e-9)  # the stance foot stays on the ground
    # touchdown of the active leg at the end: on the ground, straight, at theta0
    e = int(c.end[0])
    assert legs.foot[0, e, 1, 1] == pytest.approx(0.0, abs=1e-9)
    assert tl.theta_c[0, e, 1] == pytest.approx(p.theta0[0]) and tl.theta_l[0, e, 1] == pytest.approx(0.0, abs=1e-12)
    # the flight lasts the eq 4 time
    assert c.t[0, e] - c.t[0, n] == pytest.approx(c.T[0], rel=1e-12)


# ---------------------------------------------------------------------------- eq 12-14
def test_eval_limits_and_beta_target():
    assert M.eval_score(0.0, 0.0) == 0.0
    big = M.eval_score(1e12, 1e12)
    assert 1.0 - big < 1e-11 and big < 1.0
    assert M.eval_score(1.0, 1.0) == pytest.approx(0.5)
    g = np.linspace(0, 50, 200)
    assert np.all(np.diff(M.eval_score(g, 1.0)) > 0)
    assert M.energy_target_error(0.0, 0.0) == 0.0
    assert M.energy_target_error(7 / 3, 0.7) == pytest.approx(0.0, abs=1e-12)  # E_r = beta / (1 - beta)
    assert M.energy_target_error(1.0, 0.5) == pytest.approx(0.0)


def test_gamma_by_hand():
    s = settings()
    h = s.h
    # one DOF with constant speed through the switch: predicted == actual -> gamma 0
    theta = (0.3 * h * np.arange(6))[None, :, None]
    dt = np.full((1, 6), h)
    assert M.smoothness(theta, dt, np.array([3]), s)[0] == pytest.approx(0.0, abs=1e-12)
    # stance speeds 1, 1 (rad/s) then flight speed 3: ratio (3 + w)/(1 + w)
    th = np.array([0.0, 1 * h, 2 * h, 5 * h])[None, :, None]
    w = s.omega_floor
    assert M.smoothness(th, np.full((1, 4), h), np.array([2]), s)[0] == pytest.approx(((3 + w) / (1 + w) - 1) ** 2)
    # opposite signs: negative ratio, like the paper's max/min of signed speeds
    th = np.array([0.0, 1 * h, 2 * h, 0.0])[None, :, None]
    assert M.smoothness(th, np.full((1, 4), h), np.array([2]), s)[0] == pytest.approx((-(2 + w) / (1 + w) - 1) ** 2)


# ---------------------------------------------------------------------------- balance (eq 7-11)
def test_balance_moves_the_com_towards_the_target_on_both_axes():
    """Static legs, a target COM ahead of and right of the body: every DOF with eta > 0 leans the
    upper body so that the COM closes in on the target (the sign conventions of eq 11)."""
    s = settings(speed=2.0)
    K = 150
    tl = HB.Timeline(
        t=np.arange(K)[None] * s.h,
        dt=np.full((1, K), s.h),
        mask=np.ones((1, K), bool),
        xdot=np.full((1, K), 2.0),
        hip=np.tile([0.0, 0.9], (1, K, 1)),
        theta_c=np.zeros((1, K, 2)),
        theta_l=np.zeros((1, K, 2)),
        target=np.tile([0.10, 0.08], (1, K, 1)),
        support=np.zeros((1, K), int),
        lift=np.array([5]),
        end=np.array([K - 1]),
        l=np.array([0.9]),
    )
    D = s.body.num_dofs
    still = HB.run_balance(tl, np.zeros((1, D)), s)
    moving = HB.run_balance(tl, np.full((1, D), 5.0), s)
    assert np.allclose(still.angles, 0.0) and np.allclose(still.com[0, -1], still.com[0, 0])
    start = np.abs(tl.target[0, 0] - moving.com[0, 0, [0, 2]])
    end = np.abs(tl.target[0, -1] - moving.com[0, -1, [0, 2]])
    assert np.all(end < 0.8 * start), (start, end)
    chest_z = s.body.dof_names.index("chest.z")
    assert moving.angles[0, -1, chest_z] < 0  # leaning forward is a negative rotation about +z


def test_limp_shifts_the_com_towards_the_sound_leg():
    from charctl.experiments.hopper_ga.results import limp_test

    s = settings(speed=2.0)
    _, _, n = limp_test(np.array(GENOME_2), s, cycles=8, factor=1.5)
    assert n["limp_stance_left_s"] < 0.9 * n["limp_stance_right_s"]  # shorter stance on the limping leg
    assert abs(n["normal_stance_left_s"] - n["normal_stance_right_s"]) < 1e-9
    assert n["limp_mean_com_z_m"] > n["normal_mean_com_z_m"] + 1e-4  # towards the right (+z), sound leg


# ---------------------------------------------------------------------------- invalid individuals
def test_impossible_genomes_are_marked_invalid_not_crashed_on():
    s = settings(speed=5.0)
    good = np.array(GENOME_5)
    soft = good.copy()
    soft[1], soft[3] = s.low[1], s.high[3]  # weakest spring, heaviest HIP: collapses
    nan = good.copy()
    nan[4] = np.nan
    outside = good.copy()
    outside[0] = 5.0  # 5 m leg: outside the bounds
    scrape = good.copy()
    scrape[5], scrape[6], scrape[7] = 0.0, 0.0, 0.0  # straight swing leg under the hip: foot through the ground
    out = M.evaluate_genomes(np.stack([good, soft, nan, outside, scrape]), s)
    assert list(out["valid"]) == [True, False, False, False, False]
    assert np.isfinite(out["fitness"][0]) and np.all(np.isinf(out["fitness"][1:]))
    assert out["code"][2] & HS.BAD_GENE and out["code"][3] & HS.BAD_GENE
    assert out["code"][4] & HS.FOOT_GROUND
    assert HS.describe_invalid(int(out["code"][1])) != "valid"
    # T not real: a lift-off below y_f with too little upward speed
    assert np.isnan(HH.flight_time(0.5, 0.1, 0.8, -9.81))


def test_evaluation_rows_do_not_depend_on_the_batch():
    s = settings(speed=5.0)
    rng = np.random.default_rng(3)
    g = s.low + (s.high - s.low) * rng.random((300, len(s.low)))
    g[7] = GENOME_5
    full = M.evaluate_genomes(g, s)
    parts = [M.evaluate_genomes(c, s) for c in np.array_split(g, 7)]
    for k in full:
        np.testing.assert_array_equal(full[k], np.concatenate([p[k] for p in parts]))
    assert full["valid"].sum() >= 5


# ---------------------------------------------------------------------------- exports
def test_bvh_round_trip_matches_model_positions(tmp_path):
    from charctl.experiments.hopper_ga.character import upper_fk
    from charctl.experiments.hopper_ga.motion import run_motion, write_bvh
    from charctl.motion.bvh import read_bvh

    s = settings(speed=5.0)
    m = run_motion(np.array(GENOME_5), s, 3)
    path = write_bvh(tmp_path / "run.bvh", s, GENOME_5[0], 100.0, m.root, m.upper, m.legs)
    bvh = read_bvh(path)
    assert len(bvh.names) == 11 and bvh.num_frames == len(m.t)
    pos, _ = bvh.forward_kinematics()
    ix = {n: i for i, n in enumerate(bvh.names)}
    legs = m.rollout.legs
    for side, leg in (("right", 0), ("left", 1)):
        np.testing.assert_allclose(pos[:, ix[f"{side}_knee"]], legs.knee[0, :, leg], atol=1e-5)
        np.testing.assert_allclose(pos[:, ix[f"{side}_hip"]], legs.hip[0, :, leg], atol=1e-5)
    up, _ = upper_fk(s.body, m.root, m.upper)
    for j, name in enumerate(s.body.names):
        np.testing.assert_allclose(pos[:, ix[name]], up[:, j], atol=1e-5)


def test_render_model_kinematics_match_the_model():
    import mujoco

    from charctl.experiments.hopper_ga.character import upper_fk
    from charctl.experiments.hopper_ga.motion import joint_euler, mjcf, qpos_sequence, run_motion, skeleton

    s = settings(speed=5.0)
    m = run_motion(np.array(GENOME_5), s, 2)
    xml, hinges = mjcf(s, GENOME_5[0])
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    q = qpos_sequence(model, hinges, m.root, joint_euler(skeleton(s, GENOME_5[0]), m.upper, m.legs))
    up, _ = upper_fk(s.body, m.root, m.upper)
    for k in range(0, len(m.t), 9):
        data.qpos[:] = q[k]
        mujoco.mj_kinematics(model, data)
        for j, name in enumerate(s.body.names):
            np.testing.assert_allclose(data.body(name).xpos, up[k, j], atol=1e-4)
        np.testing.assert_allclose(data.body("left_knee").xpos, m.rollout.legs.knee[0, k, 1], atol=1e-4)
