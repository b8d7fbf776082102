"""Retarget a motion-capture file of any skeleton onto the humanoid (`charctl data import`).

Pipeline (docs/motion_import.md states each step with its equations and the decisions taken):

1. `read_source`: world joint trajectories in charctl's frame (y-up, metres), resampled to `fps`;
   scaled by s = humanoid leg length / source leg length (hip -> knee -> ankle), so the root path
   and step lengths scale with the legs. (At the end the clip is turned and moved so frame 0 faces +x
   at the origin, as the DeepMimic clips are.)
2. Planted-flat foot frames from the source (ankle low and slow), which align the feet in step 3.
3. Orientation transfer relative to each skeleton's rest frame: for every humanoid body b with source
   joint j, H_b(t) = Q_j(t) A_b, where the constant A_b (the source joint's frame seen from the
   humanoid body's rest frame) best aligns, over the whole clip, the humanoid's rest-pose directions
   (bone, hinge axis, pelvis/shoulder line, sole normal) with the same directions measured on the source
   (Wahba's problem, one SVD per body). Nothing depends on the file's zero pose, which is a T-pose in
   one convention and a bind pose of arbitrary orientations in another. Then the whole motion is shifted
   vertically so the humanoid's feet touch the ground when planted (root height from the feet).
4. Knees and elbows projected onto the humanoid's hinges (z axis, knee in [-pi, 0], elbow in [0, pi])
   by two-bone IK: the hinge angle from the law of cosines, the thigh/upper arm turned so the ankle /
   wrist lands on its target while the hinge axis stays as close as possible to the transferred one.
   Feet targets: the scaled source ankles, the foot planted in stance (`_plant_feet`: the sole corners on
   the ground do not move) and lifted clear of the ground elsewhere; hands: the source hand relative to
   its shoulder, scaled by the arm-length ratio, at the humanoid's shoulder.
5. Refinement with mink (differential IK on the project's MJCF, joint limits as QP constraints) on
   every frame where an end effector is still off its target by more than `REFINE_TOL` (targets out of
   reach: the root may then move) or a body is under the ground (that body then gets a position task
   at its depth above where it is; the feet and hands keep their targets).

The result is a `Clip` (DeepMimic layout) plus everything the quality report needs. This module is the entry
point; the steps live in `source.py` (1-2), `orient.py` (3), `ik.py` (4), `refine.py` (5), and the shared
constants, result type and humanoid numbers in `common.py`.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.motion import rotations as R
from charctl.motion.bvh_any import read_source
from charctl.motion.retarget.common import DEFAULT_FPS, Retargeted, humanoid
from charctl.motion.retarget.ik import solve_clip
from charctl.motion.retarget.orient import transfer_orientations
from charctl.motion.retarget.refine import refine_clip
from charctl.motion.retarget.source import foot_contacts, rebase_height, resample_source, scale_source, turn_and_move


# ---------------------------------------------------------------------------- entry point
def retarget(
    path: str | Path,
    skeleton: str | None = None,
    up: str | None = None,
    units: str | None = None,
    fps: float = DEFAULT_FPS,
    start: float | None = None,
    stop: float | None = None,
    name: str | None = None,
    label: str = "",
    refine: bool = True,
    ground: bool = True,
) -> Retargeted:
    """Retarget the BVH file `path` onto the humanoid; see the module docstring. `ground=False` keeps the
    source's feet as they are (no contact holding, no height fitting, no ground clearance): for clips that
    are already clean, and to check the geometric core."""
    if not (np.isfinite(fps) and fps > 0):
        raise CharctlError(f"--fps must be a finite number > 0, got {fps}")
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    src = read_source(path, skeleton, up, units, start, stop)
    times["read"] = time.perf_counter() - t0
    hum = humanoid()

    t0 = time.perf_counter()
    src = resample_source(src, fps)
    scale = hum.leg / src.leg_length()
    src = scale_source(src, scale)
    contacts = foot_contacts(src)
    H = transfer_orientations(src, contacts)
    if ground:
        src = rebase_height(src, contacts, H, hum)
    times["transfer"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    arm_scale = hum.arm / (src.arm_length())
    clip, targets, scaled, contacts = solve_clip(
        src, H, contacts, hum, arm_scale, name or Path(path).stem, label, ground
    )
    times["two_bone_ik"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    refined, iters = 0, 0
    if refine:
        clip, refined, iters = refine_clip(clip, targets, ground)
    times["mink"] = time.perf_counter() - t0
    return _canonical(Retargeted(clip, src, scale, arm_scale, scaled, targets, contacts, refined, iters, times))


def _canonical(r: Retargeted) -> Retargeted:
    """Frame 0 at x = z = 0 facing +x (the root's forward axis), as `Clip.canonicalize` puts the
    DeepMimic clips; the source and the targets move with the clip."""
    clip = r.clip
    turn = R.heading_quat(np.array(-clip.heading()[0]))
    shift = clip.root_pos[0] * np.array([1.0, 0.0, 1.0])

    def move(p: np.ndarray) -> np.ndarray:
        return R.rotate(np.broadcast_to(turn, p.shape[:-1] + (4,)), p - shift)

    r.clip = clip.canonicalize(0)
    r.source = turn_and_move(r.source, turn, shift)
    r.targets = {k: move(v) for k, v in r.targets.items()}
    r.scaled_source = {k: move(v) for k, v in r.scaled_source.items()}
    return r
