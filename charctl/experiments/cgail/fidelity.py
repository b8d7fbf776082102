"""`charctl eval RUN --fidelity`: does the policy do each commanded skill the way its clip does?

Per skill of the run, against that skill's clip (the skill data the agent loads: a `:mirror` clip is
the mirrored one):

- rollouts as the other evaluation modes make them (`rollouts.rollout_skill`): the skill commanded
  and held (no switching), deterministic mean actions, reference-state initialisation at the clip's
  frame 0 without a random yaw. Episodes last one clip length or 5 s, whichever is longer (every
  shipped clip is shorter than 5 s, so 5 s, 151 frames at 30 Hz); the world positions and rotations
  of the 15 bodies are recorded up to a fall (a non-foot body on the ground: the fall frame itself
  is not recorded). The k episodes of a skill differ only by the random heading goal of the
  locomotion skills; the others are identical (the simulator is deterministic).
- (a) mean body-position error along the DTW alignment and (b) pose coverage, in the heading frame
  (`charctl.eval.fidelity`), and (c) the signature: foot and hand peaks, airborne share, root speed,
  yaw rate, policy and clip. Episode values are averaged over the k episodes.
- (d) a filmstrip per skill: 8 clip frames spread over the clip, and above them the policy's first
  episode at the same times and the policy's closest pose to each (by the farthest body's distance).
- where the policy departs from the clip: per clip frame, the distance of its best match in each episode
  (farthest body), the stretches of the clip that fewer than half of the episodes cover with the body
  farthest there (a table column), and a plot of it for every skill (`fidelity_frames.png`).

`training_fidelity` is the cheap form for the learner: the same numbers as scalars for TensorBoard.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from charctl.eval.fidelity import (
    AIRBORNE_MARGIN,
    COVERAGE_TOL,
    PEAK_KEYS,
    body_distances,
    error_and_frame_match,
    heading_positions,
    signature,
    standing_sole_height,
    uncovered_spans,
)
from charctl.experiments.cgail.drive import policy_steps
from charctl.viz.frame_match import FramePanel, plot_frame_match
from charctl.viz.video import check_can_render  # noqa: F401  re-exported (eval_checkpoints.py)

EPISODE_SECONDS = 5.0  # minimum episode length; longer clips get one clip length
FILMSTRIP_FRAMES = 8
SIGNATURE_KEYS = (*PEAK_KEYS, "airborne", "speed", "yaw_rate")
NOT_COVERED = "not covered (clip s, farthest body, m)"  # the report column of `uncovered_cell`


@dataclass
class ClipReference:
    """One skill's clip at the control rate, as the agent loaded it, in the form the metrics take."""

    skill: str
    clip: str  # clip spec, e.g. kick:mirror
    loop: bool
    dt: float  # s between frames
    body_pos: np.ndarray  # (m, 15, 3) world
    body_rot: np.ndarray  # (m, 15, 4) world, xyzw
    rel: np.ndarray  # (m, 15, 3) heading frame, relative to the root
    qpos: np.ndarray  # (m, nq) for rendering
    ground: float  # standing sole height of the clip (its feet sink into the ground)

    @property
    def duration(self) -> float:
        return (len(self.qpos) - 1) * self.dt

    @property
    def episode_seconds(self) -> float:
        """Length of a fidelity episode for this skill: one clip length or 5 s, whichever is longer."""
        return max(EPISODE_SECONDS, self.duration)

    def signature(self) -> dict[str, float]:
        return signature(self.body_pos, self.body_rot, self.dt, self.ground)


def clip_reference(skill) -> ClipReference:
    """The `ClipReference` of a `skills.SkillData`: forward kinematics of its local rotations from its
    root positions (exactly the simulator's body positions at those states)."""
    from charctl.motion.fk import forward_kinematics
    from charctl.motion.skeleton import load_skeleton

    pos, rot = forward_kinematics(load_skeleton(), skill.qpos[:, :3], skill.local_rot)
    return ClipReference(
        skill.name,
        skill.clip_name,
        bool(skill.loop),
        1.0 / float(skill.fps),
        pos,
        rot,
        heading_positions(pos, rot[:, 0]),
        skill.qpos,
        standing_sole_height(pos, rot),
    )


@dataclass
class Recording:
    """E episodes of one commanded skill, padded to T frames; frames at and after `lengths` are not valid."""

    skill: int
    body_pos: np.ndarray  # (E, T, 15, 3) world
    body_rot: np.ndarray  # (E, T, 15, 4) world, xyzw
    qpos: np.ndarray  # (E, T, nq)
    lengths: np.ndarray  # (E,) recorded frames (frame 0 = the RSI state)
    fell: np.ndarray  # (E,) bool: the episode ended in a fall before its time was up
    dt: float


def _agent(agent_or_run):
    """The Agent behind an Agent or a loaded (Device)TrainedRun (its `.agent`). Loading a run directory is
    the caller's (evaluate.load_eval_run): this module is imported by the training loop, so it imports no
    loader (no cycle train -> fidelity -> policy -> train)."""
    return getattr(agent_or_run, "agent", agent_or_run)


def _make_env(agent, num_envs: int, seed: int, episode_seconds: float):
    """A CgailEnv of the agent's skills and env config: held commands, RSI at frame 0, no random yaw."""
    from omegaconf import OmegaConf

    from charctl.experiments.cgail.env import EVALUATION_STARTS, CgailEnv

    env_cfg = OmegaConf.merge(
        agent.cfg.env,
        {"num_envs": num_envs, "switch_prob": 0.0, "episode_seconds": episode_seconds, **EVALUATION_STARTS},
    )
    env = CgailEnv(
        agent.skills,
        env_cfg,
        seed=seed,
        conditional=agent.conditional,
        tracking=str(agent.cfg.reward.kind) == "tracking",
    )
    env.start_frame = 0
    env.random_yaw = False
    return env


@torch.no_grad()
def record_rollouts(
    agent_or_run, skills: list[int], episodes: int, seconds: list[float], seed: int = 0
) -> list[Recording]:
    """`episodes` rollouts of each skill in `skills` (skill i for `seconds[i]`), all in one env batch:
    the skill forced as the command, mean actions, RSI at the clip's frame 0 and the clip's heading.
    Each env is recorded from its reset until its time is up or it ends (a fall; the tracking
    baseline's non-looping clip ending), the frame that ends it not included."""
    agent = _agent(agent_or_run)
    hz = float(agent.cfg.env.control_hz)
    budget = np.repeat([int(round(s * hz)) for s in seconds], episodes)
    env = _make_env(agent, len(budget), seed, max(seconds) + 1.0)
    env.forced_command = np.repeat(np.asarray(skills, dtype=np.int64), episodes)
    env.reset(np.arange(env.N))
    sim = env.sim
    pos, rot, qpos = [sim.body_pos_rows()], [sim.body_quat_rows()], [sim.qpos.copy()]
    lengths = np.ones(env.N, dtype=np.int64)
    alive = np.ones(env.N, dtype=bool)
    fell = np.zeros(env.N, dtype=bool)
    for step in policy_steps(agent, env, int(budget.max())):
        res = step.result
        active = alive & (step.t < budget)  # frame step.t + 1 is within the env's budget
        fell |= res.terminated & active
        alive = active & ~(res.terminated | res.truncated)
        lengths += alive
        pos.append(sim.body_pos_rows())
        rot.append(sim.body_quat_rows())
        qpos.append(sim.qpos.copy())
        if not alive.any():
            break
    pos, rot, qpos = (np.stack(x, axis=1) for x in (pos, rot, qpos))  # (N, T, ...)
    out = []
    for i, k in enumerate(skills):
        rows = slice(i * episodes, (i + 1) * episodes)
        out.append(Recording(int(k), pos[rows], rot[rows], qpos[rows], lengths[rows], fell[rows], 1.0 / hz))
    return out


def frame_report(dist: np.ndarray, body: np.ndarray, dt: float) -> dict:
    """Which frames of the clip the E episodes do, from `frame_match` of each episode against the clip: `dist`
    (E, m) the distance of each clip frame's best match (m, at the farthest body) and `body` (E, m) that body's
    index; `dt` s between clip frames. Returns those (as `distance`, `body`), `covered_share` (m,) of the episodes
    within `COVERAGE_TOL`, and `uncovered`: each stretch of clip frames fewer than half of the episodes cover, as
    first / last frame, t0 / t1 (s), the body most often farthest there, and the largest median distance there
    (`peak_m`)."""
    from charctl.motion.skeleton import load_skeleton

    names = load_skeleton().names
    share = (dist <= COVERAGE_TOL).mean(axis=0)
    median = np.median(dist, axis=0)
    spans = []
    for a, b in uncovered_spans(share >= 0.5):
        off = body[:, a : b + 1][dist[:, a : b + 1] > COVERAGE_TOL]
        spans.append(
            {
                "first": a,
                "last": b,
                "t0": a * dt,
                "t1": b * dt,
                "body": names[int(np.bincount(off).argmax())],
                "peak_m": float(median[a : b + 1].max()),
            }
        )
    return {
        "distance": np.round(dist, 4).tolist(),
        "body": body.tolist(),
        "covered_share": share.tolist(),
        "uncovered": spans,
    }


def uncovered_cell(spans: list[dict], most: int = 3) -> str:
    """The report's cell for `frame_report`'s spans: the `most` longest, in clip order, e.g.
    "0.27-1.10 s left_wrist 0.35 m"; "-" when every frame is covered."""
    if not spans:
        return "-"
    longest = sorted(sorted(spans, key=lambda s: s["first"] - s["last"])[:most], key=lambda s: s["first"])
    cell = "; ".join(
        (f"{s['t0']:.2f} s" if s["first"] == s["last"] else f"{s['t0']:.2f}-{s['t1']:.2f} s")
        + f" {s['body']} {s['peak_m']:.2f} m"
        for s in longest
    )
    return cell + (f"; +{len(spans) - most} more" if len(spans) > most else "")


def score_recording(rec: Recording, ref: ClipReference) -> dict:
    """The fidelity numbers of one skill's episodes against its clip (episode values averaged)."""
    rel = heading_positions(rec.body_pos, rec.body_rot[..., 0, :])
    per_episode = [error_and_frame_match(rel[e, :n], ref.rel, ref.loop) for e, n in enumerate(rec.lengths)]
    errors, dist, body = (np.array(x) for x in zip(*per_episode))  # (E,), (E, m), (E, m)
    coverages = (dist <= COVERAGE_TOL).mean(axis=1)  # as body_error_and_coverage
    sig = signature(rec.body_pos, rec.body_rot, rec.dt, 0.0, rec.lengths)
    return {
        "clip": ref.clip,
        "coverage": float(coverages.mean()),
        "body_error": float(errors.mean()),
        "policy": {k: float(np.mean(sig[k])) for k in SIGNATURE_KEYS},
        "reference": ref.signature(),
        "no_fall": float(1.0 - rec.fell.mean()),
        "episodes": len(rec.lengths),
        "seconds_recorded": float((rec.lengths.mean() - 1) * rec.dt),
        "episode_seconds": ref.episode_seconds,
        "frames": frame_report(dist, body, ref.dt),
        "per_episode": {
            "coverage": coverages.tolist(),
            "body_error": errors.tolist(),
            "fell": rec.fell.tolist(),
            "frames": rec.lengths.tolist(),
            **{k: np.asarray(sig[k]).tolist() for k in SIGNATURE_KEYS},
        },
    }


def write_skill_filmstrip(
    rec: Recording, ref: ClipReference, path: Path, title: str, shoulder_frame: str = "parent"
) -> Path:
    """Filmstrip of `rec`'s first episode against the clip: the clip's frames in the bottom row, the
    policy at the same times above them, and on top of those the policy's closest pose to each. Both qpos
    are of the model built with `shoulder_frame` (the run's env.shoulder_frame)."""
    from charctl.sim.humanoid import load_model
    from charctl.viz.filmstrip import write_filmstrip

    n = int(rec.lengths[0])
    cols = np.unique(np.round(np.linspace(0, len(ref.qpos) - 1, FILMSTRIP_FRAMES)).astype(int))
    t = cols * ref.dt
    same = np.minimum(np.round(t / rec.dt).astype(int), n - 1)
    rel = heading_positions(rec.body_pos[0, :n], rec.body_rot[0, :n, 0])
    worst = body_distances(rel, ref.rel[cols]).max(axis=-1)  # (n, cols)
    near = worst.argmin(axis=0)
    near_d = worst[near, np.arange(len(cols))]
    fell_at = n * rec.dt if rec.fell[0] else None
    same_titles = [
        f"t={s * rec.dt:.2f} s" + (" (fallen)" if fell_at is not None and tt >= fell_at else "")
        for s, tt in zip(same, t)
    ]
    return write_filmstrip(
        load_model(shoulder_frame=shoulder_frame),
        [rec.qpos[0, near], rec.qpos[0, same], ref.qpos[cols]],
        path,
        ["policy: closest pose", "policy: same time", f"clip {ref.clip}"],
        [
            [f"t={i * rec.dt:.2f} s, {d:.2f} m" for i, d in zip(near, near_d)],
            same_titles,
            [f"t={x:.2f} s" for x in t],
        ],
        title=title,
    )


# ---------------------------------------------------------------------------- eval mode
def eval_fidelity(runs: list, episodes: int, out: Path, seed: int = 2468, filmstrips: bool = True) -> dict:
    """`charctl eval RUN... --fidelity [-k N]`: per run and skill, fidelity.json, a table in report.md
    and (with `filmstrips`) fidelity_<skill>.png (fidelity_<run>_<skill>.png for several runs)."""
    from charctl.eval.report import markdown_table, print_table, write_json
    from charctl.experiments.cgail.report import append_report

    labels = [tr.label for tr in runs]
    several = len(runs) > 1
    skills_out: dict[str, dict] = {}
    rows: dict[str, dict] = {}
    written = []
    for tr in runs:
        label = tr.label if labels.count(tr.label) == 1 else tr.run_dir.name
        refs = [clip_reference(s) for s in tr.agent.skills]
        recs = record_rollouts(tr, list(range(len(refs))), episodes, [r.episode_seconds for r in refs], seed=seed)
        panels = []
        for rec, ref in zip(recs, refs):
            key = f"{ref.skill} ({label})" if several else ref.skill
            res = score_recording(rec, ref)
            res["run"] = str(tr.run_dir)
            if filmstrips:
                stem = f"fidelity_{tr.run_dir.name}_{ref.skill}" if several else f"fidelity_{ref.skill}"
                write_skill_filmstrip(
                    rec,
                    ref,
                    out / f"{stem}.png",
                    f"{ref.skill} ({label}, {tr.run_dir.name}): coverage {res['coverage']:.2f}, "
                    f"body error {res['body_error']:.3f} m",
                    shoulder_frame=tr.cfg.env.shoulder_frame,
                )
                res["filmstrip"] = f"{stem}.png"
                written.append((key, f"{stem}.png"))
            skills_out[key] = res
            rows[key] = _table_row(res)
            panels.append(_frame_panel(res, ref))
        if filmstrips:
            name = f"fidelity_frames_{tr.run_dir.name}.png" if several else "fidelity_frames.png"
            plot_frame_match(
                panels, out / name, COVERAGE_TOL, f"{label} ({tr.run_dir.name}): where each skill departs from its clip"
            )
            written.append((f"{label}: per clip frame", name))
    result = {
        "skills": skills_out,
        "episodes": episodes,
        "seed": seed,
        "runs": {tr.run_dir.name: str(tr.run_dir) for tr in runs},
        "coverage_tolerance_m": COVERAGE_TOL,
        "airborne_margin_m": AIRBORNE_MARGIN,
        "metric": METRIC_NOTE,
    }
    write_json(out / "fidelity.json", result)
    cols = list(next(iter(rows.values())))
    # the terminal table leaves out the long "not covered" text, printed below it one skill per line
    print_table(
        f"Fidelity per skill ({episodes} episodes each; cells policy / clip)",
        rows,
        [c for c in cols if c != NOT_COVERED],
    )
    print(f"{NOT_COVERED} ({COVERAGE_TOL:g} m at every body):")
    for key, row in rows.items():
        print(f"  {key}: {row[NOT_COVERED]}")
    body = markdown_table(rows, cols)
    if written:
        body += "\n\n" + "\n".join(f"![{k}]({f})" for k, f in written)
    append_report(out, f"Fidelity — {episodes} episodes per skill", body, METRIC_NOTE)
    return result


METRIC_NOTE = (
    "held command, mean actions, RSI at the clip's frame 0, episodes of max(clip length, 5 s) recorded up to a "
    "fall; body error: mean over the aligned frames (DTW against the clip, looping clips tiled) of the mean "
    "distance of the 15 bodies, positions relative to the root in its heading frame; coverage: share of the "
    f"clip's frames some policy frame matches within {COVERAGE_TOL:g} m at every body; peaks: highest y of the "
    f"ankle / wrist origin; airborne: share of frames with both foot soles {AIRBORNE_MARGIN:g} m above standing "
    "(the floor for the policy, the clip's own standing sole height for the clip); speed: mean horizontal root "
    "speed; yaw rate: mean |d heading / dt|; cells policy / clip, policy values averaged over the episodes; not "
    "covered: the longest stretches of clip frames fewer than half of the episodes match, with the body most often "
    "farthest there and the largest median distance of a frame's best match (fidelity_frames.png plots it)"
)


def _frame_panel(res: dict, ref: ClipReference) -> FramePanel:
    spans = [(s["t0"], s["t1"], s["body"]) for s in res["frames"]["uncovered"]]
    title = f"{ref.skill} (clip {ref.clip}): coverage {res['coverage']:.2f}"
    return FramePanel(title, ref.dt, np.asarray(res["frames"]["distance"]), spans)


def _table_row(res: dict) -> dict[str, str | float]:
    p, c = res["policy"], res["reference"]

    def pair(key: str, digits: int = 2) -> str:
        return f"{p[key]:.{digits}f} / {c[key]:.{digits}f}"

    return {
        "coverage": res["coverage"],
        "body error (m)": res["body_error"],
        "R foot peak (m)": pair("right_foot_peak"),
        "L foot peak (m)": pair("left_foot_peak"),
        "R hand peak (m)": pair("right_hand_peak"),
        "L hand peak (m)": pair("left_hand_peak"),
        "airborne": pair("airborne"),
        "speed (m/s)": pair("speed"),
        "yaw rate (rad/s)": pair("yaw_rate"),
        "no-fall": res["no_fall"],
        NOT_COVERED: uncovered_cell(res["frames"]["uncovered"]),
    }


# ---------------------------------------------------------------------------- during training
def training_fidelity(agent_or_run, num_envs: int = 2, seconds: float | None = None, seed: int = 0) -> dict[str, float]:
    """Fidelity scalars of the agent's current policy, for TensorBoard during training.

    `agent_or_run`: the learner's `train.Agent` (its policy is used as it is, on its device; the
    function builds its own CgailEnv from `agent.skills` and `agent.cfg.env`, so the training envs are
    untouched), a loaded run, or a run directory. `num_envs` episodes per skill, all skills in one
    env batch; `seconds` per episode (None: max(clip length, 5 s) per skill, as `--fidelity`). Returns
    `fidelity/<skill>/coverage`, `.../body_error` (m), `.../foot_peak` (m, the higher of both feet's
    peaks), `.../airborne`, `.../yaw_rate` (rad/s) and `fidelity/min_coverage` (over the skills); the
    definitions are `charctl eval RUN --fidelity`'s, without the filmstrips."""
    agent = _agent(agent_or_run)
    refs = [clip_reference(s) for s in agent.skills]
    lengths = [r.episode_seconds if seconds is None else float(seconds) for r in refs]
    recs = record_rollouts(agent, list(range(len(refs))), max(1, int(num_envs)), lengths, seed=seed)
    out: dict[str, float] = {}
    for rec, ref in zip(recs, refs):
        res = score_recording(rec, ref)
        p = res["policy"]
        out[f"fidelity/{ref.skill}/coverage"] = res["coverage"]
        out[f"fidelity/{ref.skill}/body_error"] = res["body_error"]
        ep = res["per_episode"]
        out[f"fidelity/{ref.skill}/foot_peak"] = float(np.mean(np.maximum(ep["right_foot_peak"], ep["left_foot_peak"])))
        out[f"fidelity/{ref.skill}/airborne"] = p["airborne"]
        out[f"fidelity/{ref.skill}/yaw_rate"] = p["yaw_rate"]
    out["fidelity/min_coverage"] = min(out[f"fidelity/{r.skill}/coverage"] for r in refs)
    return out
