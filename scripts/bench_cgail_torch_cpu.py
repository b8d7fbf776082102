"""Would one torch cgail env (both backends) be as fast on the CPU as the numpy one? Per-step cost, one run:

    .venv/bin/python scripts/bench_cgail_torch_cpu.py [--envs 256] [--rounds 4]

Times the env's work outside the simulator on one torch thread (as `collect_rollout` runs it), float64,
as thread CPU time (10th percentile and median of 300 calls), so load from other processes inflates both
sides less than wall time would:

1. features: `features.sim_kinematics` + policy state + disc obs (numpy, today's CPU path) against the
   same from `torch.from_numpy` views of MuJoCo's arrays (no copies), once through the shared array-API
   `features.py` as the warp env and web graph use it, and once as a hand-written torch port (3x3 matrices,
   one shared heading frame, no array-API layer);
2. a control step without physics (`sim.step` stubbed, 3 resets per step): `CgailEnv.step` against a
   torch port of its default path (`TorchStepPrototype` below: features, goal reward, episode ends, fall
   rates, ramp, with the numpy RNG and numpy resets kept, which favours the port).

Both torch forms are checked against numpy (float64, ~1e-14) before timing. docs/cgail.md, "Throughput
(CPU)", records the numbers and the decision they led to.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from charctl.experiments.cgail import features as F
from charctl.experiments.cgail.env import CgailEnv
from charctl.motion import rotations_torch as RT
from charctl.motion.skeleton import END_EFFECTORS, load_skeleton


def cpu_us(fn, n: int = 300) -> tuple[int, int]:
    """(10th percentile, median) thread CPU time of `fn()`, microseconds."""
    fn()
    ts = []
    for _ in range(n):
        t0 = time.thread_time()
        fn()
        ts.append(time.thread_time() - t0)
    ts.sort()
    return round(ts[n // 10] * 1e6), round(ts[n // 2] * 1e6)


def _two_columns(m: torch.Tensor) -> torch.Tensor:
    return torch.cat([m[..., :, 0], m[..., :, 1]], -1)


class TorchStepPrototype(CgailEnv):
    """`CgailEnv` whose default step path (no tracking, no pose error) runs in torch over views of
    MuJoCo's arrays; measurement only."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        sim, skel = self.sim, load_skeleton()
        self.t_xpos, self.t_xquat = torch.from_numpy(sim.xpos), torch.from_numpy(sim.xquat)
        self.t_cvel, self.t_sc = torch.from_numpy(sim.cvel), torch.from_numpy(sim.subtree_com)
        self.bid = torch.as_tensor(sim.body_ids)
        self.masses, self.mass = torch.as_tensor(skel.masses), float(sim.model.body_subtreemass[1])
        self.com_local = torch.as_tensor(skel.com_local)[:, :, None]
        self.ee = torch.as_tensor([skel.index(n) for n in END_EFFECTORS])
        joints = np.asarray(skel.clip_joint_bodies)
        self.joints, self.parents = torch.as_tensor(joints), torch.as_tensor(np.asarray(skel.parents)[joints])
        # views of the numpy env state, so the numpy resets and command switches stay in effect
        self.t_cmd, self.t_w = torch.from_numpy(self.cmd), torch.from_numpy(self.w)
        self.t_goal, self.t_has_goal = torch.from_numpy(self.goal_angle), torch.from_numpy(self.has_goal)
        self.t_speed, self.t_rate = torch.from_numpy(self.speed), torch.from_numpy(self.fall_rate.copy())
        self.t_rest = torch.zeros(sim.layout.nu, dtype=torch.float64)

    def kinematics(self):
        pos = self.t_xpos[:, self.bid]
        q = self.t_xquat[:, self.bid]
        rot = torch.cat([q[..., 1:4], q[..., :1]], -1)
        cv = self.t_cvel[:, self.bid]
        ang, lin_c = cv[..., :3], cv[..., 3:]
        lin = lin_c + torch.cross(ang, pos - self.t_sc[:, 1:2], dim=-1)
        mat = RT.to_matrix(rot)
        offset = torch.matmul(mat, self.com_local)[..., 0]
        com_vel = torch.einsum("nbi,b->ni", lin + torch.cross(ang, offset, dim=-1), self.masses) / self.mass
        return pos, rot, lin, ang, self.t_sc[:, 1].clone(), com_vel, mat

    def features(self, goal: bool = True):
        """(state (N, 243) or (N, 241) without `goal`, disc obs (N, 133), COM velocity (N, 3))."""
        pos, rot, lin, ang, com, com_vel, mat = self.kinematics()
        n, root = pos.shape[0], pos[:, 0]
        heading = RT.yaw_about_y(rot[:, 0])
        h = RT.to_matrix(RT.heading_quat(-heading))
        h_t = h.transpose(1, 2)
        rel, lin_h, ang_h = torch.matmul(pos - root[:, None], h_t), torch.matmul(lin, h_t), torch.matmul(ang, h_t)
        parts = [
            root[:, 1:2],
            rel[:, 1:].reshape(n, -1),
            _two_columns(torch.matmul(h[:, None], mat)).reshape(n, -1),
            lin_h.reshape(n, -1),
            ang_h.reshape(n, -1),
            torch.matmul((com - root)[:, None], h_t)[:, 0],
            torch.matmul(com_vel[:, None], h_t)[:, 0],
            rel[:, self.ee].reshape(n, -1),
        ]
        if goal:
            g = self.t_goal - heading
            parts.append(torch.stack([torch.cos(g), torch.sin(g)], 1) * self.t_has_goal[self.t_cmd][:, None])
        local = torch.matmul(mat[:, self.parents].transpose(-1, -2), mat[:, self.joints])
        obs = [root[:, 1:2], lin_h[:, 0], ang_h[:, 0], _two_columns(local).reshape(n, -1)]
        obs += [lin_h[:, 1:].reshape(n, -1), rel[:, self.ee].reshape(n, -1)]
        return torch.cat(parts, 1), torch.cat(obs, 1), com_vel

    def torch_step(self, actions: torch.Tensor):
        unstable = torch.from_numpy(self.sim.step((self.t_rest + self.cfg.action_scale * actions).numpy()))
        final_state, pair_next, com_vel = self.features()
        g, cmd = self.t_goal, self.t_cmd
        along = torch.cos(g) * com_vel[:, 0] - torch.sin(g) * com_vel[:, 2]
        r = torch.exp(-self.cfg.goal_sharpness * (self.t_speed[cmd] - along) ** 2)
        r_goal = torch.where(self.t_has_goal[cmd], r, torch.ones_like(r))
        fell = torch.from_numpy(self.sim.non_foot_ground_contact(self.cfg.fall_tolerance))
        terminated = fell | unstable
        steps = torch.from_numpy(self.steps)
        steps += 1
        truncated = (steps >= self.max_steps) & ~terminated
        self.fall_count += int(fell.sum())
        done = torch.nonzero(terminated | truncated)[:, 0]
        if done.numel():
            ended = cmd[done]
            m = torch.bincount(ended, minlength=self.K).double()
            f = torch.bincount(ended, weights=fell[done].double(), minlength=self.K)
            keep = 0.5 ** (m / self.cfg.skill_fall_halflife)
            self.t_rate = keep * self.t_rate + (1 - keep) * (f / m.clamp(min=1.0))
        state, obs = final_state.clone(), pair_next.clone()
        if self.cfg.ramp_frames > 0:
            torch.clamp(self.t_w + 1.0 / self.cfg.ramp_frames, max=1.0, out=self.t_w)
        if done.numel():
            self.reset(done.numpy())
        running = torch.ones(self.N, dtype=torch.bool)
        running[done] = False
        self._maybe_switch(np.flatnonzero(running.numpy()))
        return state, obs, pair_next, final_state, r_goal, terminated, truncated, unstable


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--envs", type=int, default=256)
    ap.add_argument("--rounds", type=int, default=4)
    a = ap.parse_args()
    from charctl.config import compose_config
    from charctl.experiments.cgail.agent import build_agent
    from charctl.experiments.cgail.config import Config

    torch.set_num_threads(1)  # as collect_rollout
    cfg = compose_config("cgail", ["scale=small", f"env.num_envs={a.envs}"], Config)
    skills = build_agent(cfg, training=False).skills
    numpy_env, torch_env = CgailEnv(skills, cfg.env, seed=0), TorchStepPrototype(skills, cfg.env, seed=0)
    N, nu = numpy_env.N, numpy_env.sim.layout.nu
    actions, t_actions = np.zeros((N, nu)), torch.zeros(N, nu, dtype=torch.float64)
    for _ in range(3):  # real physics, so the states are not the RSI ones
        numpy_env.step(actions)
        torch_env.torch_step(t_actions)
    sim = torch_env.sim

    def numpy_features():
        k = F.sim_kinematics(sim)
        f = F.heading_frame(k)
        return F.policy_state(k, f), F.disc_obs(k, f)

    def shared_features():
        pos, rot, lin, ang, com, com_vel, _ = torch_env.kinematics()
        k = F.Kinematics(pos, rot, lin, ang, com, com_vel)
        f = F.heading_frame(k)
        return F.policy_state(k, f), F.disc_obs(k, f)

    s_np, o_np = numpy_features()
    for name, (s, o) in {
        "shared array-API": shared_features(),
        "hand port": torch_env.features(goal=False)[:2],
    }.items():
        err = max(float((s - torch.from_numpy(s_np)).abs().max()), float((o - torch.from_numpy(o_np)).abs().max()))
        print(f"torch {name} features - numpy: max |diff| {err:.1e}")
        assert err < 1e-12
    for env in (numpy_env, torch_env):  # no physics from here on; 3 envs end every step
        env.sim.step = lambda *args, **kwargs: np.zeros(N, dtype=bool)
        env.sim.non_foot_ground_contact = lambda tol: np.isin(np.arange(N), [0, N // 3, 2 * N // 3])
    print(f"{N} envs, thread CPU time per call, (p10, median) us")
    with torch.inference_mode():
        for r in range(a.rounds):
            print(
                f"  round {r + 1}: features numpy {cpu_us(numpy_features)}, torch shared "
                f"{cpu_us(shared_features)}, torch hand port {cpu_us(lambda: torch_env.features(goal=False))}; "
                f"step w/o physics numpy {cpu_us(lambda: numpy_env.step(actions))}, "
                f"torch {cpu_us(lambda: torch_env.torch_step(t_actions))}"
            )


if __name__ == "__main__":
    main()
