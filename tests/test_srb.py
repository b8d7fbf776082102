"""srb: QP tracker, integrator, contact schedule, reference, termination, touch-down rules, push
protocol, and the end-to-end smoke run (train, --resume, eval --push, export --video).

Independent references: a second QP solver on the paper's full formulation (quadprog through
qpsolvers, equality-constrained Newton-Euler) vs the bound-only reduced form solved by daqp;
closed-form free fall of semi-implicit Euler; MuJoCo's joint-space mass matrix for the composite
inertia; hand-built states for termination and touch-down rules.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from charctl.experiments.srb.config import Config
from charctl.experiments.srb.qp import GRAVITY, N_EDGES, QPBatch, QPParams, friction_basis, full_problem, solve_batch
from charctl.motion import rotations as R

from conftest import assert_one_line

torch = pytest.importorskip("torch")
torch.set_num_threads(1)


def make_cfg(**overrides):
    return OmegaConf.merge(
        OmegaConf.structured(Config), OmegaConf.from_dotlist([f"{k}={v}" for k, v in overrides.items()])
    )


@pytest.fixture(scope="module")
def walk():
    from charctl.motion.library import load_clip

    return load_clip("walk")


@pytest.fixture(scope="module")
def ref(walk):
    from charctl.experiments.srb.reference import build_reference

    return build_reference(walk)


@pytest.fixture(scope="module")
def body(walk):
    from charctl.experiments.srb.env import make_body

    return make_body(walk, 60.0)


def make_env(ref, body, n=1, **overrides):
    from charctl.experiments.srb.env import SRBEnv

    return SRBEnv(make_cfg(**overrides), n, seed=0, reference=ref, body=body, auto_reset=False, max_steps=10**6)


# ---------------------------------------------------------------------------- QP
def random_batch(rng, n, spread=0.25):
    com = np.c_[rng.normal(0, 0.1, n), rng.uniform(0.7, 1.0, n), rng.normal(0, 0.1, n)]
    pts = com[:, None, :] + rng.normal(0, spread, (n, 4, 3))
    pts[..., 1] = 0.0
    active = rng.random((n, 4)) < 0.7
    a = rng.normal(size=(n, 3, 3))
    inertia = np.einsum("nij,nkj->nik", a, a) + 2.0 * np.eye(3)
    return QPBatch(pts, active, com, inertia, rng.normal(size=(n, 3)), rng.normal(0, 20, (n, 6)))


@pytest.mark.parametrize("torque_limit", [0.0, 30.0])
def test_qp_satisfies_newton_euler_and_friction_cone_and_matches_quadprog(torque_limit):
    import qpsolvers

    rng = np.random.default_rng(7)
    batch = random_batch(rng, 40)
    params = QPParams(mass=60.0, mu=0.8, torque_limit=torque_limit, torque_reg=1e-3)
    out = solve_batch(batch, params, "daqp")
    assert (out["flags"] >= 0).all()
    a, wdot, f, tau = out["qdd"][:, :3], out["qdd"][:, 3:], out["forces"], out["tau"]
    # Newton: m a = sum f + m g ; Euler: I wdot + w x I w = sum r x f + tau
    np.testing.assert_allclose(60.0 * a, f.sum(1) + 60.0 * GRAVITY, atol=1e-6)
    r = batch.points - batch.com[:, None, :]
    iw = np.einsum("nij,nj->ni", batch.inertia, batch.ang_vel)
    lhs = np.einsum("nij,nj->ni", batch.inertia, wdot) + np.cross(batch.ang_vel, iw)
    np.testing.assert_allclose(lhs, np.cross(r, f).sum(1) + tau, atol=1e-6)
    # friction pyramid |f_x|, |f_z| <= mu f_n, f_n >= 0; no force at swing points; torque bound
    fn = f[..., 1]
    assert (fn >= -1e-7).all()
    assert (np.abs(f[..., 0]) <= 0.8 * fn + 1e-6).all() and (np.abs(f[..., 2]) <= 0.8 * fn + 1e-6).all()
    assert np.abs(f[~batch.active]).max() <= 1e-9
    assert (np.abs(tau) <= torque_limit + 1e-7).all()
    assert (out["lambda"] >= -1e-9).all()
    # the paper's full problem (variables q_dd, lambda, tau with equality constraints) by quadprog
    for i in range(batch.com.shape[0]):
        fp = full_problem(batch, params, i)
        z = qpsolvers.solve_qp(fp["P"], fp["q"], A=fp["A"], b=fp["b"], lb=fp["lb"], ub=fp["ub"], solver="quadprog")
        assert z is not None
        np.testing.assert_allclose(z[:6], out["qdd"][i], atol=1e-5)
        forces = np.einsum("ij,cj->ci", friction_basis(0.8), z[6:22].reshape(4, N_EDGES))
        np.testing.assert_allclose(forces, f[i], atol=1e-3)


def test_qp_solver_paths_agree():
    rng = np.random.default_rng(3)
    batch = random_batch(rng, 10)
    params = QPParams(mass=60.0, mu=1.0, torque_limit=30.0, torque_reg=1e-3)
    base = solve_batch(batch, params, "daqp")["qdd"]
    for solver in ("qpsolvers:daqp", "qpsolvers:quadprog"):
        np.testing.assert_allclose(solve_batch(batch, params, solver)["qdd"], base, atol=1e-5)


def test_qp_tracks_a_feasible_target_exactly():
    # a desired acceleration reachable inside the cone must be tracked (residual ~ regulariser)
    batch = QPBatch(
        points=np.array([[[-0.1, 0, -0.1], [0.1, 0, -0.1], [-0.1, 0, 0.1], [0.1, 0, 0.1]]]),
        active=np.ones((1, 4), bool),
        com=np.array([[0.0, 0.9, 0.0]]),
        inertia=np.eye(3)[None] * 5.0,
        ang_vel=np.zeros((1, 3)),
        acc_des=np.array([[0.5, 1.0, -0.3, 0.0, 0.0, 0.0]]),
    )
    out = solve_batch(batch, QPParams(mass=60.0, mu=1.0), "daqp")
    np.testing.assert_allclose(out["qdd"], batch.acc_des, atol=1e-3)


# ---------------------------------------------------------------------------- integrator / standing
def test_free_fall_matches_semi_implicit_euler_closed_form(ref, body):
    env = make_env(ref, body)
    env.pos[:] = [0.0, 5.0, 0.0]
    env.vel[:] = [1.0, 2.0, 0.0]
    env.ang_vel[:] = 0.0
    env.rot[:] = R.IDENTITY
    h, n = 1.0 / 120.0, 60
    for _ in range(n):
        env.advance_body(np.zeros((1, 6)), env.contact_points(), np.zeros((1, 4), bool), None, h)
    g = -9.81
    assert env.pos[0, 1] == pytest.approx(5.0 + 2.0 * n * h + g * h * h * n * (n + 1) / 2, abs=1e-9)
    assert env.pos[0, 0] == pytest.approx(1.0 * n * h, abs=1e-12)
    t = n * h
    assert env.pos[0, 1] == pytest.approx(
        5.0 + 2.0 * t + 0.5 * g * t * t, abs=abs(g) * h * t
    )  # O(h) of the exact parabola


def test_torque_free_rotation_conserves_angular_momentum(ref, body):
    env = make_env(ref, body)  # no foot on the ground: the body torque is off too (torque_limit applies in contact)
    env.pos[:] = [0.0, 50.0, 0.0]
    env.vel[:] = 0.0
    env.rot[:] = R.normalize(np.array([[0.1, 0.2, 0.05, 1.0]]))
    env.ang_vel[:] = [[0.3, 1.0, -0.5]]
    momentum0 = env.world_inertia()[0] @ env.ang_vel[0]
    for _ in range(600):  # 1 s at 600 Hz, no contacts, no desired acceleration reachable
        env.advance_body(np.zeros((1, 6)), env.contact_points(), np.zeros((1, 4), bool), None, 1.0 / 600.0)
    momentum1 = env.world_inertia()[0] @ env.ang_vel[0]
    assert np.linalg.norm(momentum1 - momentum0) < 0.01 * np.linalg.norm(momentum0)


@pytest.mark.parametrize("torque_limit", [0.0, 30.0])
def test_standing_with_zero_desired_acceleration_stays_up(ref, body, torque_limit):
    env = make_env(ref, body, **{"tracking.torque_limit": torque_limit})
    env.pos[:] = [0.0, 0.85, 0.0]
    env.vel[:] = 0.0
    env.ang_vel[:] = 0.0
    env.rot[:] = R.IDENTITY
    env.foot_pos[:] = [[[0.0, 0.0, 0.1], [0.0, 0.0, -0.1]]]
    env.foot_yaw[:] = 0.0
    env.stance[:] = True
    active = np.ones((1, 4), bool)
    for _ in range(60):  # 2 s at 30 Hz
        out = env.advance_body(np.zeros((1, 6)), env.contact_points(), active, None, 1.0 / 30.0)
    assert env.pos[0] == pytest.approx([0.0, 0.85, 0.0], abs=1e-4)
    assert np.degrees(2 * np.arccos(min(1.0, abs(env.rot[0, 3])))) < 0.01
    np.testing.assert_allclose(out["forces"].sum(1)[0], [0.0, 60.0 * 9.81, 0.0], atol=1e-3)


def test_pd_tracking_follows_the_reference_when_torque_is_free(ref, body):
    # the tracker alone (zero action, unbounded body torque, no touch-down frame shifts) follows the
    # walk within a few cm for two cycles; with the 30 N m bound it drifts (the policy's job)
    errors = {}
    for limit in (1e4, 30.0):
        env = make_env(ref, body, n=4, **{"tracking.torque_limit": limit, "touchdown.enabled": False})
        env.reset(frames=np.array([0, 10, 20, 30]))
        for _ in range(2 * ref.cycle):
            env.step(np.zeros((4, 10)))
        errors[limit] = np.linalg.norm(env.pos - ref.state(env.frame)["pos"], axis=1)
    assert (errors[1e4] < 0.06).all()
    assert errors[30.0].max() > 0.2


# ---------------------------------------------------------------------------- reference / schedule
def test_contact_schedule_alternates_feet_and_matches_foot_heights(walk, ref):
    from charctl.experiments.srb.reference import sole_points_world, transitions

    stance = ref.stance
    assert not (~stance[:, 0] & ~stance[:, 1]).any()  # a walk has no flight phase
    heights = sole_points_world(walk)[: ref.cycle, :, :, 1].min(axis=2)  # lower sole point (T, 2)
    assert (heights[stance] < 0.03).all()  # a stance foot is within 3 cm of the ground
    swings = []
    for j in range(2):
        downs, ups = transitions(stance[:, j])
        assert len(downs) == 1 and len(ups) == 1  # one swing per foot per cycle
        length = (downs[0] - ups[0]) % ref.cycle
        swing = (ups[0] + np.arange(length)) % ref.cycle
        assert 8 <= length <= 22 and heights[swing, j].max() > 0.1  # a real step: the foot rises > 10 cm
        swings.append(set(swing.tolist()))
    assert not swings[0] & swings[1]  # right and left swings alternate, separated by double support
    # the right foot swings in the second half of the cycle, the left in the first (this clip)
    assert np.mean(sorted(swings[0])) > np.mean(sorted(swings[1]))


def test_merge_short_runs_is_cyclic():
    from charctl.experiments.srb.reference import merge_short_runs

    m = np.array([1, 1, 0, 1, 1, 1, 0, 0, 0, 0, 1], dtype=bool)
    out = merge_short_runs(m, 3, cyclic=True)
    np.testing.assert_array_equal(out, [1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 1])
    np.testing.assert_array_equal(
        merge_short_runs(np.array([0, 0, 1, 0, 0, 0], bool), 2, cyclic=False), np.zeros(6, bool)
    )


def test_reference_is_continuous_across_cycles(ref):
    c = ref.cycle
    s = ref.state(np.array([c - 1, c, c + 1, 2 * c - 1, 2 * c]))
    step = np.linalg.norm(np.diff(s["pos"], axis=0), axis=1)
    assert step[0] < 0.08 and step[1] < 0.08 and step[3] < 0.08  # a frame of walking, no jump at the wrap
    assert R.angle_between(s["rot"][0], s["rot"][1]) < 0.1
    # finite-difference velocity at the wrap matches the stored one
    fd = (s["pos"][2] - s["pos"][0]) * ref.fps / 2
    np.testing.assert_allclose(fd, s["vel"][1], atol=1e-9)


def test_composite_inertia_matches_mujoco_mass_matrix(walk, body):
    import mujoco

    from charctl.experiments.srb.reference import composite_inertia
    from charctl.sim.humanoid import load_model, local_rot_to_qpos

    inertia, mass, com = composite_inertia(walk, 0)
    model = load_model()
    data = mujoco.MjData(model)
    data.qpos[:] = local_rot_to_qpos(walk.root_pos[0], walk.local_rot[0])
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    # free-joint rotational block = inertia about the root origin in the root frame; parallel axis to the COM
    about_root = full[3:6, 3:6]
    expected = about_root - mass * (com @ com * np.eye(3) - np.outer(com, com))
    assert mass == pytest.approx(45.0)
    np.testing.assert_allclose(inertia, expected, atol=1e-6)
    np.testing.assert_allclose(body.inertia, inertia * 60.0 / 45.0, atol=1e-9)
    hx, hy, hz = body.half_extents  # the render box has the same principal moments
    assert 60.0 / 3.0 * (hy**2 + hz**2) == pytest.approx(body.inertia[0, 0], rel=1e-6)


# ---------------------------------------------------------------------------- termination / touch-down
def test_termination_rules(ref, body):
    env = make_env(ref, body, n=6)
    env.reset(frames=np.zeros(6, dtype=int))
    tilt = lambda deg: R.from_axis_angle(np.array([1.0, 0.0, 0.0]), np.radians(deg))  # noqa: E731
    env.pos[0, 1] = 0.19  # below min(0.7 y_ref, 0.2) = 0.2
    env.pos[1, 1] = 0.25  # above it: the literal min(...) keeps a low but upright body alive
    env.pos[2, 1] = 2.05  # above 2.0
    env.rot[3] = tilt(71.0)
    env.rot[4] = tilt(69.0)
    np.testing.assert_array_equal(env.terminated(), [True, False, True, True, False, False])
    env2 = make_env(ref, body, n=2, **{"termination.max_steps": 3})
    env2.max_steps = 3
    for _ in range(3):
        _, _, terminal, truncated, info = env2.step(np.zeros((2, 10)))
    assert truncated.all() and not terminal.any() and info["done_idx"].tolist() == [0, 1]


def test_late_touchdown_makes_the_reference_wait(ref, body):
    env = make_env(ref, body, **{"touchdown.max_delay": 3})
    td = int(np.flatnonzero(ref.stance[:, 0] & ~np.roll(ref.stance[:, 0], 1))[0])  # right touch-down frame
    env.reset(frames=np.array([td - 1]))
    env.pos[0, 1] = ref.state(np.array([td]))["pos"][0, 1] + 0.05  # too high to reach the ground
    for k in range(3):
        env.advance_reference()
        assert env.frame[0] == td - 1 and not env.stance[0, 0] and env.delay[0] == k + 1
    env.advance_reference()  # the delay budget is spent: the foot lands
    assert env.frame[0] == td and env.stance[0, 0] and env.delay[0] == 0


def test_early_touchdown_jumps_to_the_touchdown_frame(ref, body):
    env = make_env(ref, body)
    up = int(np.flatnonzero(~ref.stance[:, 0] & np.roll(ref.stance[:, 0], 1))[0])  # right lift-off
    td = int(ref.next_touchdown[up, 0])
    late_swing = up + int(np.ceil(0.75 * (td - up)))
    env.reset(frames=np.array([late_swing - 1]))
    env.pos[0, 1] = ref.touchdown_height - 0.05
    env.vel[0, 1] = -0.4
    env.advance_reference()
    assert env.frame[0] == td and env.stance[0, 0] and env.vel[0, 1] == 0.0
    env.reset(frames=np.array([up]))  # right after lift-off a low COM does not jump (early_min_swing)
    env.pos[0, 1] = ref.touchdown_height - 0.05
    env.advance_reference()
    assert env.frame[0] == up + 1 and not env.stance[0, 0]


def test_observation_layout(ref, body):
    env = make_env(ref, body, n=3)
    obs = env.reset(frames=np.array([0, 5, 25]))
    assert obs.shape == (3, 20)
    s = ref.state(np.array([0, 5, 25]))
    np.testing.assert_allclose(obs[:, 0], s["pos"][:, 1])
    np.testing.assert_allclose(np.linalg.norm(obs[:, 1:5], axis=1), 1.0)
    assert np.allclose(R.yaw_about_y(obs[:, 1:5]), 0.0, atol=1e-9)  # heading removed
    np.testing.assert_allclose(obs[:, 19], np.array([0, 5, 25]) / ref.cycle)
    np.testing.assert_allclose(obs[:, 14][env.stance[:, 0]], 0.0)


def test_rotation_fast_paths_match_scipy():
    """The component-wise forms the srb control loop uses (broadcasting rotate, yaw of +x, rotate_yaw,
    log_map, to_matrix, multiply) against scipy's Rotation (an independent implementation)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    q = R.normalize(rng.normal(size=(50, 4)))
    v = rng.normal(size=(50, 3))
    rot = Rotation.from_quat(q)
    np.testing.assert_allclose(R.rotate(q, v), rot.apply(v), atol=1e-12)
    np.testing.assert_allclose(R.rotate(q[:1], v), Rotation.from_quat(q[0]).apply(v), atol=1e-12)  # broadcast
    product = Rotation.from_quat(R.multiply(q, q[::-1])).as_matrix()
    np.testing.assert_allclose(product, (rot * rot[::-1]).as_matrix(), atol=1e-12)  # sign-free comparison
    fwd = rot.apply([1.0, 0.0, 0.0])
    np.testing.assert_allclose(R.yaw_about_y(q), np.arctan2(-fwd[:, 2], fwd[:, 0]), atol=1e-9)
    np.testing.assert_allclose(
        R.rotate_yaw(np.full(50, 0.7), v), Rotation.from_rotvec([0.0, 0.7, 0.0]).apply(v), atol=1e-12
    )
    np.testing.assert_allclose(R.up_y(q), rot.apply([0.0, 1.0, 0.0])[:, 1], atol=1e-12)
    np.testing.assert_allclose(R.log_map(q), rot.as_rotvec(), atol=1e-9)
    np.testing.assert_allclose(R.to_matrix(q), rot.as_matrix(), atol=1e-12)


# ---------------------------------------------------------------------------- push protocol
def test_push_case_semantics():
    from charctl.experiments.srb.push import PushCase, window_fraction

    c = PushCase("impulse", 300.0, 0.2, 90.0, 0.5, settle_s=1.0)
    np.testing.assert_allclose(
        c.direction_world(np.array(0.0)), [0.0, 0.0, -1.0], atol=1e-12
    )  # left of a +x walker is -z
    np.testing.assert_allclose(
        PushCase("impulse", 1, 1, 0.0, 0).direction_world(np.array(np.pi / 2)), [0, 0, -1], atol=1e-12
    )
    assert c.impulse_ns == pytest.approx(60.0) and c.start_s == pytest.approx(1.0 + 0.5 * c.cycle_s)
    dt = 1 / 30
    t = np.arange(0, 2, dt)
    for dur in (0.01, 0.1, 0.2, 1.0):  # the impulse delivered over control steps is exact
        frac = window_fraction(t, dt, np.full_like(t, 0.5), np.full_like(t, dur))
        assert (frac * dt).sum() == pytest.approx(dur, abs=1e-12)


def test_run_push_study_table_and_largest_force():
    from charctl.experiments.srb.push import comparison_markdown, make_cases, run_push_study

    cfg = make_cfg(
        **{
            "push.forces": "[100,200,300,400]",
            "push.durations": "[0.1,0.4]",
            "push.directions": "[0,180]",
            "push.phases": "[0.0,0.5]",
        }
    )
    cases = make_cases(cfg.push)
    assert len(cases) == (1 + 4 + 2) * 2 * 2 and cases[0].kind == "control" and cases[0].force_n == 0.0
    seen = []

    def fake(case, seed):  # survives impulses below 50 N s, and 60 N s only forwards
        seen.append(seed)
        return case.impulse_ns < 50 or (case.impulse_ns < 70 and case.direction_deg == 0.0)

    table = run_push_study(fake, cases, trials=3, seed=10, progress=False)
    assert sorted(set(seen)) == [10, 11, 12]
    assert table.survival("impulse", 200, 0.2) == 1.0 and table.survival("impulse", 300, 0.2) == 0.5
    assert table.survival("impulse", 400, 0.2) == 0.0 and table.survival("sustained", 100, 0.4) == 1.0
    ls = table.largest_survived(0.5)
    assert (
        ls["largest_force_rate"] == 300
        and ls["largest_force_all_survived"] == 200
        and ls["first_force_with_fall"] == 300
    )
    md = comparison_markdown([table, None], ["SRB", "full body"], 0.5, "no cgail run")
    assert "| 300 N for 0.2 s | 60 | 0.50 | — |" in md and "full body: missing (no cgail run)" in md
    batch = run_push_study(None, cases, 3, seed=10, simulate_batch=lambda jobs: [fake(c, s) for c, s in jobs])
    np.testing.assert_array_equal(batch.outcomes, table.outcomes)


# ---------------------------------------------------------------------------- end to end
def test_smoke_train_resume_push_and_video(tmp_path, smoke_run_copy):
    from charctl.commands.evaluate import eval_command
    from charctl.commands.export import export_command
    from charctl.commands.train import train_command
    from charctl.errors import CharctlError

    run_dir = smoke_run_copy(
        "srb"
    )  # `charctl train srb scale=smoke`, the user's path, once per session (test_smoke.py)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["samples"] == 2048 and metrics["iterations"] == 2 and metrics["qp_failures"] == 0
    assert 1 <= metrics["episode_length"] <= 90 and (run_dir / "checkpoints" / "last.pt").is_file()
    assert (run_dir / "training_curve.png").stat().st_size > 1000

    # the rest in-process (same code paths as the CLI, without paying the imports again)
    train_command("srb", ["train.total_samples=3072"], resume=run_dir)
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert metrics["samples"] == 3072 and metrics["iterations"] == 3

    options = {
        "dtw": False,
        "confusion": False,
        "switch": None,
        "curves": False,
        "pose_error": False,
        "push": True,
        "sweep": False,
        "episodes": 1,
        "out": None,
    }
    eval_command([str(run_dir)], options)
    report = (run_dir / "push" / "report.md").read_text()
    assert "Full-body baseline missing" in report and "| 300 N for 0.2 s |" in report
    data = json.loads((run_dir / "push" / "push.json").read_text())
    assert len(data["srb"]["outcomes"]) == (1 + 2 + 2) * 2 and data["full_body"] is None
    assert "| no push | 0 |" in report
    assert (run_dir / "push" / "push.png").stat().st_size > 1000

    with pytest.raises(CharctlError) as err:
        eval_command([str(run_dir)], {**options, "push": False, "dtw": True})
    assert_one_line(err.value, "--dtw")
    try:
        export_command(str(run_dir), [], {"video": tmp_path / "srb.mp4", "seconds": 0.4})
    except CharctlError as exc:
        if "cannot render" in str(exc):
            pytest.skip("no offscreen renderer on this machine")
        raise
    assert (tmp_path / "srb.mp4").stat().st_size > 1000


def test_bad_config_is_one_line(tmp_path):
    from charctl.commands.train import train_command
    from charctl.errors import CharctlError

    with pytest.raises(CharctlError) as err:
        train_command("srb", ["scale=smoke", "tracking.solver=cvxopt", f"output_root={tmp_path}"])
    assert_one_line(err.value, "tracking.solver")
    with pytest.raises(CharctlError) as err:
        train_command("srb", ["scale=smoke", "tracking.kpp=3", f"output_root={tmp_path}"])
    assert_one_line(err.value, "tracking.kpp")


def test_full_body_baseline_is_found_and_run_through_the_protocol(tmp_path, monkeypatch):
    import charctl.experiments.cgail.push as cgail_push
    from charctl.experiments.srb.evaluate import _baseline_label, _baseline_table, find_baseline_run
    from charctl.experiments.srb.push import make_cases

    def fake_run(name, conditional, skills):
        d = tmp_path / "repro" / "cgail" / name
        (d / "checkpoints").mkdir(parents=True)
        (d / "checkpoints" / "last.pt").write_bytes(b"x")
        (d / "config.yaml").write_text(
            f"experiment: cgail\ncgail: {{conditional: {str(conditional).lower()}}}\nuse_skills: {skills}\n"
        )
        return d

    fake_run("2026-01-01_00-00-00", False, "[walk]")
    newest_amp = fake_run("2026-01-02_00-00-00", False, "[walk]")
    fake_run("2026-01-03_00-00-00", True, "[walk]")  # cGAIL, not the baseline
    fake_run("2026-01-04_00-00-00", False, "[walk, run]")  # AMP but several skills
    assert find_baseline_run(tmp_path) == str(newest_amp)
    assert _baseline_label(str(newest_amp)).startswith("full body (AMP walk")
    calls = []
    monkeypatch.setattr(
        cgail_push,
        "make_push_simulator",
        lambda run_dir: lambda case, seed: calls.append((run_dir, seed)) or case.force_n < 250,
    )
    cases = make_cases(
        make_cfg(
            **{"push.forces": "[200,300]", "push.durations": "[0.1]", "push.directions": "[0]", "push.phases": "[0.0]"}
        ).push
    )
    table, note = _baseline_table(str(newest_amp), cases, 2, seed=5)
    assert note == "" and len(calls) == len(cases) * 2 and {s for _, s in calls} == {5, 6}
    assert table.survival("impulse", 200, 0.2) == 1.0 and table.survival("impulse", 300, 0.2) == 0.0
    assert _baseline_table("", cases, 2, seed=5)[0] is None
