"""The cgail controller as one torch graph over MuJoCo's own arrays, exported to ONNX for the web demo.

`charctl export RUN --web DIR` (docs/web.md) runs the policy in a browser: MuJoCo in WebAssembly
steps the humanoid and onnxruntime-web evaluates this graph once per control step. The page copies
MuJoCo's arrays in and the PD targets out; everything in between is computed here, by the project's
own functions (`features.policy_state` / `disc_obs` on torch tensors, the policy's normaliser and MLP,
the discriminator's class head), so there is no second implementation of the features in JavaScript.

Inputs (batch B, float64; MuJoCo's arrays as `mjData` holds them after a step, all bodies and geoms of
the model including the world body 0):
    xpos (B, nbody, 3), xquat (B, nbody, 4) wxyz, cvel (B, nbody, 6), subtree_com (B, nbody, 3)
    geom_xpos (B, ngeom, 3), geom_xmat (B, ngeom, 9)
    skill_from, skill_to, ramp_w (B,): the command A -> B and the ramp weight w (eq 4.10)
    goal_skill, goal_yaw (B,): the command whose heading goal the state carries and the goal's world yaw
        (radians about +y). The env computes s_t at the end of a control step, before a switch between
        steps takes effect, so for the step after a switch these are still the previous command's
        (the page keeps them latched one step; the blend uses the new A, B, w at once).
    prev_obs (B, 133): the `obs` output of the previous control step (the classifier's o_t)
    phase (B, 2): only in the graph of a run trained with env.phase_obs: (cos, sin) of the commanded clip's
        timed reference frame, (0, 0) for skills with a heading goal and while a ramp runs (env._phase_features;
        the page keeps the reference frame, web/sim.js)
Outputs:
    ctrl (B, nu): PD targets (radians; rest pose + action_scale * mean action), for `mjData.ctrl`
    state (B, 243; 245 with phase): the policy state s_t; command (B, K): the blend c̄ = (1 - w) onehot(A) + w onehot(B)
    obs (B, 133): the discriminator observation o_t; probs (B, K): softmax of the class head on
        (prev_obs, obs) (zeros for an AMP run); style (B,): r_S = clip(1 - (1 - D)^2 / 4, 0, 1) (eq 4.7)
    fell (B,): 1 where a non-foot geom is within env.fall_tolerance of the ground (the env's fall rule)
"""

from __future__ import annotations

import warnings

import numpy as np
import torch
from torch import nn

from charctl.errors import CharctlError
from charctl.experiments.cgail.discriminator import frozen_copy
from charctl.experiments.cgail.features import (
    DISC_OBS_DIM,
    Kinematics,
    disc_obs,
    heading_frame,
    policy_state,
)
from charctl.experiments.cgail.rules import goal_features
from charctl.motion import rotations_torch as RT
from charctl.motion.skeleton import FEET, load_skeleton

INPUTS = (
    "xpos",
    "xquat",
    "cvel",
    "subtree_com",
    "geom_xpos",
    "geom_xmat",
    "skill_from",
    "skill_to",
    "ramp_w",
    "goal_skill",
    "goal_yaw",
    "prev_obs",
)
OUTPUTS = ("ctrl", "state", "command", "obs", "probs", "style", "fell")

# MuJoCo geom type codes (mjtGeom) of the humanoid's shapes
_SPHERE, _CAPSULE, _BOX = 2, 3, 6


def mujoco_kinematics(
    xpos: torch.Tensor,
    xquat: torch.Tensor,
    cvel: torch.Tensor,
    subtree_com: torch.Tensor,
    body_ids: torch.Tensor,
    masses: torch.Tensor,
    com_local: torch.Tensor,
    total_mass: float,
) -> Kinematics:
    """`features.sim_kinematics` from mjData arrays (B, nbody, ...): body frames in charctl order,
    world linear velocities of the frame origins (cvel is [angular, linear] at the root's subtree COM),
    whole-body COM and its velocity (mass-weighted velocities of the body COMs)."""
    pos = xpos[:, body_ids]
    rot = RT.wxyz_to_xyzw(xquat[:, body_ids])
    cv = cvel[:, body_ids]
    ang, lin_c = cv[..., :3], cv[..., 3:]
    com = subtree_com[:, 1]
    lin = lin_c + RT.cross(ang, pos - com[:, None])
    offset = RT.rotate(rot, com_local.expand(pos.shape))  # body COM - frame origin, world
    com_vel = ((lin + RT.cross(ang, offset)) * masses[None, :, None]).sum(1) / total_mass
    return Kinematics(pos, rot, lin, ang, com, com_vel)


class WebGraph(nn.Module):
    """MuJoCo arrays + command ramp -> PD targets and what the page shows (module docstring)."""

    def __init__(self, tr, model):
        super().__init__()
        if tr.cfg.reward.kind == "tracking":
            raise CharctlError(
                f"{tr.run_dir} is a tracking run: its policy needs the reference clip's phase, which the web demo "
                "does not play; export a cgail (adversarial) run"
            )
        self.phase_obs = bool(getattr(tr.cfg.env, "phase_obs", False))  # the `phase` input (module docstring)
        skel = load_skeleton()
        body_ids = np.array([model.body(n).id for n in skel.names])
        self.register_buffer("body_ids", torch.as_tensor(body_ids))
        self.register_buffer("masses", torch.as_tensor(skel.masses, dtype=torch.float64))
        self.register_buffer("com_local", torch.as_tensor(skel.com_local, dtype=torch.float64))
        self.total_mass = float(model.body_subtreemass[1])
        self.K = len(tr.skill_names)
        self.register_buffer(
            "has_goal", torch.as_tensor([float(s.heading_goal) for s in tr.agent.skills], dtype=torch.float64)
        )
        self.register_buffer("skill_ids", torch.arange(self.K, dtype=torch.float64))
        self.policy = _MeanAction(tr.agent.model)
        self.action_scale = float(tr.cfg.env.action_scale)
        self.register_buffer("rest", torch.zeros(model.nu, dtype=torch.float64))
        self.fall_tolerance = float(tr.cfg.env.fall_tolerance)
        # the character's geoms (not the floor) and which of them are feet: batch.BatchedHumanoid's fall rule
        feet = {model.body(n).id for n in FEET}
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] != 0]
        non_foot = [g for g in geoms if model.geom_bodyid[g] not in feet]
        self.register_buffer("fall_geoms", torch.as_tensor(non_foot))
        self.register_buffer("geom_size", torch.as_tensor(model.geom_size[non_foot], dtype=torch.float64))
        gtype = model.geom_type[non_foot]
        if not np.isin(gtype, [_SPHERE, _CAPSULE, _BOX]).all():
            raise CharctlError("the humanoid has a geom that is not a sphere, capsule or box")
        self.register_buffer("is_sphere", torch.as_tensor(gtype == _SPHERE, dtype=torch.float64))
        self.register_buffer("is_capsule", torch.as_tensor(gtype == _CAPSULE, dtype=torch.float64))
        self.register_buffer("is_box", torch.as_tensor(gtype == _BOX, dtype=torch.float64))
        # discriminator: frozen copies of the spectral-normalised layers (the weights as the checkpoint uses them)
        disc = tr.agent.disc
        self.conditional = disc.class_head is not None
        self.register_buffer("disc_mean", disc.norm.mean.detach().clone().float())
        self.register_buffer("disc_std", torch.sqrt(disc.norm.var + disc.norm.eps).detach().clone().float())
        self.disc_clip = float(disc.norm.clip)
        frozen = frozen_copy(disc)
        self.disc_trunk, self.style_head, self.class_head = frozen.trunk, frozen.style_head, frozen.class_head
        self.per_skill_style = bool(getattr(disc, "per_skill", False))

    def lowest_heights(self, geom_xpos: torch.Tensor, geom_xmat: torch.Tensor) -> torch.Tensor:
        """(B, G) lowest world y of every non-foot character geom (`batch._lowest_y`: spheres r, capsules
        r + half |axis_y|, boxes sum_k |R_yk| h_k)."""
        pos = geom_xpos[:, self.fall_geoms]
        mat = geom_xmat[:, self.fall_geoms]  # row-major 3x3: entries 3..5 are the world-y row
        size = self.geom_size
        ext = (
            self.is_sphere * size[:, 0]
            + self.is_capsule * (size[:, 0] + size[:, 1] * mat[..., 5].abs())
            + self.is_box * (mat[..., 3:6].abs() * size).sum(-1)
        )
        return pos[..., 1] - ext

    def forward(
        self,
        xpos: torch.Tensor,
        xquat: torch.Tensor,
        cvel: torch.Tensor,
        subtree_com: torch.Tensor,
        geom_xpos: torch.Tensor,
        geom_xmat: torch.Tensor,
        skill_from: torch.Tensor,
        skill_to: torch.Tensor,
        ramp_w: torch.Tensor,
        goal_skill: torch.Tensor,
        goal_yaw: torch.Tensor,
        prev_obs: torch.Tensor,
        phase: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, ...]:
        k = mujoco_kinematics(
            xpos, xquat, cvel, subtree_com, self.body_ids, self.masses, self.com_local, self.total_mass
        )
        f64 = xpos.dtype
        onehot_from = (self.skill_ids[None, :] == skill_from[:, None]).to(f64)
        onehot_to = (self.skill_ids[None, :] == skill_to[:, None]).to(f64)
        onehot_goal = (self.skill_ids[None, :] == goal_skill[:, None]).to(f64)
        w = ramp_w[:, None]
        command = (1.0 - w) * onehot_from + w * onehot_to
        # heading goal (rules.goal_features): the goal's direction relative to the heading, 0 without a goal
        goal = goal_features(goal_yaw, RT.yaw_about_y(k.body_rot[:, 0]), (onehot_goal @ self.has_goal) > 0.5)
        f = heading_frame(k)
        parts = [policy_state(k, f), goal] + ([phase] if self.phase_obs else [])
        state = torch.cat(parts, dim=1)
        # the networks in float32, fed as the trainer feeds them (float64 features rounded to float32)
        action = self.policy(state.float(), command.float())
        ctrl = self.rest + self.action_scale * action.to(f64)
        obs = disc_obs(k, f)
        pair = torch.cat([prev_obs, obs], dim=1).float()
        x = torch.clamp((pair - self.disc_mean) / self.disc_std, -self.disc_clip, self.disc_clip)
        h = self.disc_trunk(x)
        d = self.style_head(h)
        d = (d * command.float()).sum(-1) if self.per_skill_style else d[:, 0]
        style = torch.clamp(1.0 - 0.25 * (1.0 - d) ** 2, 0.0, 1.0).to(f64)
        if self.class_head is not None:
            probs = torch.softmax(self.class_head(h), dim=-1).to(f64)
        else:
            probs = torch.zeros_like(command)
        fell = (self.lowest_heights(geom_xpos, geom_xmat) < self.fall_tolerance).any(dim=1).to(f64)
        return ctrl, state, command, obs, probs, style, fell


class _MeanAction(nn.Module):
    """The trained ActorCritic's own mean action: its observation normaliser, then the actor MLP on the
    normalised state with the command appended (the command is ignored by an unconditional run)."""

    def __init__(self, model: nn.Module):
        super().__init__()
        self.model = model

    def forward(self, state: torch.Tensor, command: torch.Tensor) -> torch.Tensor:
        return self.model.mean_action(state, command)


def graph_inputs(phase_obs: bool) -> tuple[str, ...]:
    """The graph's input names: INPUTS, and `phase` for a run trained with env.phase_obs."""
    return (*INPUTS, "phase") if phase_obs else INPUTS


def example_inputs(model, K: int, batch: int = 1, phase_obs: bool = False) -> tuple[torch.Tensor, ...]:
    """Inputs of the right shapes (the rest pose's arrays), for tracing the export."""
    import mujoco

    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)

    def arr(a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.repeat(a[None], batch, axis=0), dtype=torch.float64)

    zeros = torch.zeros(batch, dtype=torch.float64)
    phase = (torch.zeros(batch, 2, dtype=torch.float64),) if phase_obs else ()
    return (
        arr(data.xpos),
        arr(data.xquat),
        arr(data.cvel),
        arr(data.subtree_com),
        arr(data.geom_xpos),
        arr(data.geom_xmat),
        zeros,
        zeros,
        torch.ones(batch, dtype=torch.float64),
        zeros,
        zeros,
        torch.zeros(batch, DISC_OBS_DIM, dtype=torch.float64),
        *phase,
    )


def _atan2_float64(g, y, x):
    """ONNX for aten::atan2 on float64 inputs: ONNX Runtime has no float64 Atan, so the float32 atan2 of
    the exporter's own symbolic gives θ0 (error ~1e-7 rad) and one step in float64 makes it exact to
    rounding: θ = θ0 + (y cos θ0 - x sin θ0) / (x cos θ0 + y sin θ0) (= θ0 + tan δ; δ^3 ~ 1e-21)."""
    from torch.onnx import symbolic_opset9 as s9

    theta0 = s9.atan2(g, g.op("Cast", y, to_i=1), g.op("Cast", x, to_i=1))  # 1 = FLOAT
    theta0 = g.op("Cast", theta0, to_i=11)  # 11 = DOUBLE
    c, s = g.op("Cos", theta0), g.op("Sin", theta0)
    num = g.op("Sub", g.op("Mul", y, c), g.op("Mul", x, s))
    den = g.op("Add", g.op("Mul", x, c), g.op("Mul", y, s))
    return g.op("Add", theta0, g.op("Div", num, den))


def export_web_onnx(tr, model, path) -> None:
    """Write the graph as ONNX (batch axis dynamic), inputs and outputs named as in the module docstring."""
    graph = WebGraph(tr, model).eval()
    inputs = example_inputs(model, graph.K, batch=2, phase_obs=graph.phase_obs)
    names = graph_inputs(graph.phase_obs)
    dyn = {name: {0: "batch"} for name in (*names, *OUTPUTS)}
    opset = 17
    torch.onnx.register_custom_op_symbolic("aten::atan2", _atan2_float64, opset)
    try:
        with torch.no_grad(), warnings.catch_warnings():
            # the skeleton's index and mass tables become graph constants, as intended
            warnings.simplefilter("ignore", torch.jit.TracerWarning)
            torch.onnx.export(
                graph,
                inputs,
                str(path),
                input_names=list(names),
                output_names=list(OUTPUTS),
                dynamic_axes=dyn,
                opset_version=opset,
                dynamo=False,
            )
    finally:
        torch.onnx.unregister_custom_op_symbolic("aten::atan2", opset)
