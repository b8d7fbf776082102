"""The SRB side of the push protocol: batched rollouts of a trained (or zero-action) SRB policy
under the pushes of charctl.experiments.srb.push, shared by the push study (evaluate.py) and the
push video (export.py)."""

from __future__ import annotations

import math

import numpy as np

from charctl.experiments.srb.push import PushCase, iter_chunks, window_fraction
from charctl.motion import rotations as R

CHUNK = 512  # push episodes stepped together per SRBEnv


def zero_actions(model, obs: np.ndarray) -> np.ndarray:
    """The 'no policy' ablation: feet at the reference placement, no velocity offsets (QP + PD only)."""
    return np.zeros((obs.shape[0], 10))


def srb_push_batch(
    run, jobs: list[tuple[PushCase, int]], record: bool = False, zero_action: bool = False
) -> list[bool] | tuple[list[bool], dict]:
    """Survival of the trained SRB policy for every (case, seed): deterministic policy, episode from
    reference frame 0 with a seed-drawn perturbation of the initial velocities (push.init_noise).
    `zero_action` replaces the policy by zero actions (what the QP tracker alone achieves)."""
    from charctl.experiments.srb.env import SRBEnv
    from charctl.experiments.srb.train import load_policy, policy_actions

    agent, _ = load_policy(run)
    act = zero_actions if zero_action else policy_actions
    cfg = run.cfg
    results: list[bool] = []
    traces = None
    proto = SRBEnv(cfg, 1, seed=0, auto_reset=False)
    for chunk in iter_chunks(jobs, CHUNK):
        env = SRBEnv(cfg, len(chunk), seed=0, reference=proto.ref, body=proto.body, auto_reset=False, max_steps=10**9)
        survived, traces = simulate_chunk(env, agent.model, chunk, float(cfg.push.init_noise), act, record)
        results.extend(survived.tolist())
    return (results, traces) if record else results


def simulate_chunk(env, model, chunk, init_noise: float, act, record: bool, seconds: float | None = None):
    """Step one SRBEnv whose environment e runs chunk[e] = (case, seed); survived (n,) and, with
    `record`, the trajectory (then every environment runs `seconds` or the longest case in full)."""
    n = len(chunk)
    env.reset(frames=np.zeros(n, dtype=int))
    for e, (_, seed) in enumerate(chunk):
        rng = np.random.default_rng(seed)
        env.vel[e] += rng.normal(0.0, init_noise, 3)
        env.ang_vel[e] += rng.normal(0.0, init_noise, 3)
    force = np.array([c.force_n for c, _ in chunk])
    duration = np.array([c.duration_s for c, _ in chunk])
    phase = np.array([c.phase for c, _ in chunk])
    settle = np.array([c.settle_s for c, _ in chunk])
    observe = np.array([c.observe_s for c, _ in chunk])
    direction = np.radians([c.direction_deg for c, _ in chunk])
    start = np.full(n, np.inf)
    push_dir = np.zeros((n, 3))
    fallen = np.zeros(n, dtype=bool)
    dt, cycle = env.dt, env.ref.cycle
    steps = int(math.ceil((seconds if seconds else max(c.total_s for c, _ in chunk)) / dt)) + 1
    trace = {"pos": [], "rot": [], "feet": [], "stance": [], "forces": [], "push": []} if record else None
    obs = env.observe()
    u_prev = env.frame / cycle
    for k in range(steps):
        t = k * dt
        u = env.frame / cycle
        if k > 0:  # the push opens at the first step after settle_s whose reference phase reached `phase`
            crossed = np.floor(u - phase) > np.floor(u_prev - phase)
            opening = ~np.isfinite(start) & (t >= settle) & (crossed | (np.abs((u - phase) % 1.0) < 1e-9))
            if opening.any():
                start[opening] = t
                a = R.yaw_about_y(env.rot) + direction
                push_dir[opening] = np.stack([np.cos(a), np.zeros_like(a), -np.sin(a)], axis=-1)[opening]
        u_prev = u
        frac = window_fraction(np.full(n, t), dt, start, duration)
        push = (force * frac)[:, None] * push_dir
        obs, _, terminal, _, _ = env.step(act(model, obs), push)
        fallen |= terminal & ~fallen & (t < start + duration + observe)
        if record:
            for key, val in (
                ("pos", env.pos),
                ("rot", env.rot),
                ("feet", env.contact_points()),
                ("stance", env.stance),
                ("forces", env.last_forces),
                ("push", push),
            ):
                trace[key].append(np.array(val, copy=True))
        if not record and np.all(fallen | (t + dt >= start + duration + observe)):
            break
        if fallen.any() and not record:  # keep fallen bodies numerically tame; their outcome is recorded
            env.reset(np.flatnonzero(fallen), frames=env.frame[fallen])
            obs = env.observe()
    never = ~np.isfinite(start)  # the phase never came (cannot happen with settle + one cycle, kept honest)
    survived = ~fallen & ~never
    if record:
        trace = {k: np.stack(v) for k, v in trace.items()}
        trace["dt"] = dt
        trace["start"], trace["duration"] = start, duration
    return survived, trace
