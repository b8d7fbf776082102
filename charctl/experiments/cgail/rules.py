"""The cgail environment's rules, written once for both backends (numpy on the CPU, torch on the device).

Pure functions of batched arrays (leading dim N): the heading-goal and clip-phase parts of the policy
state, the DeepMimic-style tracking reward, the reference pose error, the heading-goal reward, the
episode ends, and the per-env bookkeeping (command switches and the ramp weight, the timed reference's
restart and grace steps, the pose-error check and its reward, `reference_check`). `env.CgailEnv` calls
them with numpy arrays (env.backend=cpu), with torch tensors (env.backend=warp / torch) and the web graph
(`charctl.motion.array_compat`), so a rule change is one edit.

Frames and units (docs/cgail.md): the disc observation o (133) is in the heading frame (+x facing, y up,
+z right), metres, m/s, radians; yaw angles are about world +y.
"""

from __future__ import annotations

import math

from charctl.motion.array_compat import Array, device_of, namespace

GOAL_DIM = 2  # (cos, sin) of the heading goal relative to the heading (`goal_features`)
PHASE_DIM = 2  # (cos, sin) of the clip phase (`phase_features`): tracking baseline and env.phase_obs


def phase_in_state(cfg) -> bool:
    """Whether the policy state of a run with config `cfg` ends with the clip phase: the tracking baseline and
    env.phase_obs."""
    return cfg.reward.kind == "tracking" or bool(cfg.env.phase_obs)


def state_dim(phase: bool) -> int:
    """Width of the policy state: the features (`features.STATE_DIM`), the heading goal and, for the
    tracking baseline or a run with env.phase_obs (`phase`), the clip phase."""
    from charctl.experiments.cgail.features import STATE_DIM

    return STATE_DIM + GOAL_DIM + (PHASE_DIM if phase else 0)


# DeepMimic-style tracking reward (reward.kind=tracking), computed on the discriminator
# observation o (heading frame, so it is invariant to the character's yaw): weights and scales
# of the pose, velocity, end-effector and root ("COM") terms. See docs/cgail.md, "Tracking baseline".
TRACK_WEIGHTS = {"pose": 0.65, "vel": 0.1, "ee": 0.15, "root": 0.1}
TRACK_SCALES = {"pose": 1.0, "vel": 0.1, "ee": 40.0, "root_height": 10.0, "root_vel": 1.0}
OBS_YAW_RATE = 5  # column of o: the root's angular velocity about +y (rad/s; the heading frame's y is world up)
# slices of o: root height, root linear velocity, joint rotations (12x6), body velocities (14x3), end effectors (4x3)
OBS_ROOT_H, OBS_ROOT_V, OBS_ROT, OBS_VEL, OBS_EE = (
    slice(0, 1),
    slice(1, 4),
    slice(7, 79),
    slice(79, 121),
    slice(121, 133),
)


def tracking_reward(obs: Array, ref: Array) -> Array:
    """(N,) r in [0, 1] between simulated and reference disc observations (N, 133).

    r = 0.65 exp(-1 sum_j |rot6_j - rot6*_j|^2) + 0.1 exp(-0.1 sum_b |v_b - v*_b|^2)
      + 0.15 exp(-40 sum_e |p_e - p*_e|^2) + 0.1 exp(-10 (h - h*)^2 - |v_root - v*_root|^2)
    (joint rotations as the first two rotation-matrix columns; velocities in m/s; positions in m,
    relative to the root in the heading frame).
    """
    xp = namespace(obs, ref)

    def sq(sl: slice) -> Array:
        return xp.sum((obs[:, sl] - ref[:, sl]) ** 2, axis=1)

    w, k = TRACK_WEIGHTS, TRACK_SCALES
    root = xp.exp(-k["root_height"] * sq(OBS_ROOT_H) - k["root_vel"] * sq(OBS_ROOT_V))
    return (
        w["pose"] * xp.exp(-k["pose"] * sq(OBS_ROT))
        + w["vel"] * xp.exp(-k["vel"] * sq(OBS_VEL))
        + w["ee"] * xp.exp(-k["ee"] * sq(OBS_EE))
        + w["root"] * root
    )


def pose_keys(obs: Array) -> Array:
    """(..., 13) the parts of disc observations (..., 133) the pose error compares: root height, then the
    four end effectors' positions (m, relative to the root in the heading frame)."""
    xp = namespace(obs)
    return xp.concat([obs[..., OBS_ROOT_H], obs[..., OBS_EE]], axis=-1)


def pose_key_error(a: Array, b: Array, root_scale: float = 1.0) -> Array:
    """(...) m: the largest of the four end-effector distances and `root_scale` times the root-height
    difference between `pose_keys` arrays `a` and `b` (..., 13), which broadcast (e.g. (n, 1, 13) against
    (1, T, 13)). `root_scale` = pose threshold / root-height threshold (`root_height_scale`) makes one
    comparison with the pose threshold check both."""
    xp = namespace(a, b)
    d = a[..., 1:] - b[..., 1:]
    d = d.reshape(d.shape[:-1] + (4, 3))
    ee = xp.sqrt(xp.max(xp.sum(d * d, axis=-1), axis=-1))  # sqrt of the largest square: the largest distance
    return xp.maximum(ee, root_scale * xp.abs(a[..., 0] - b[..., 0]))


def pose_key_error_frames(keys: Array, frames: Array, root_scale: float = 1.0) -> Array:
    """(n, T) m: `pose_key_error` of `pose_keys` arrays `keys` (n, 13) against T frames each, given frames last
    as `frames` (n, 13, T) (a clip's `pose_keys` with the frame axis moved to the end): the same operations on
    the same numbers, so the same values, laid out so that every one runs along the frames (the closest-frame
    search of the pose error; over the frame-first layout, sums and maxima over axes of 3 and 4 are slow in torch)."""
    xp = namespace(keys, frames)
    d = keys[:, 1:, None] - frames[:, 1:]
    d = xp.reshape(d, (d.shape[0], 4, 3, d.shape[-1]))
    ee = xp.sqrt(xp.max(xp.sum(d * d, axis=2), axis=1))
    return xp.maximum(ee, root_scale * xp.abs(keys[:, :1] - frames[:, 0]))


def goal_reference_frame(
    each: Array, advanced: Array, loops: Array, clip_frames: Array, window: int, synced: Array
) -> Array:
    """(n,) the clip frame each heading-goal row is scored against (reward.goal_reference_window).

    `each` (n, T) m the pose error of each row against every frame of its clip (columns past a clip's length
    repeat frames); `advanced` (n,) the row's reference frame after this step's `advance_reference`;
    `loops`, `clip_frames` (n,) its clip's; `synced` (n,) bool its reference is checked (running, out of its
    grace steps). `window` 0: the closest frame of the whole clip (a walk may stay on a few frames: a
    shuffle). `window` w > 0, where `synced`: the closest of the w frames from `advanced` on (cyclic over a
    looping clip's period, T - 1 frames), so the reference moves on by 1 to w frames per control step and the
    whole gait cycle is asked for; elsewhere (grace steps, ramps) the whole clip, which re-synchronises it."""
    xp = namespace(each, advanced)
    if window <= 0:
        return xp.argmin(each, axis=1)
    period = xp.where(loops, xp.clip(clip_frames - 1, min=1), clip_frames)[:, None]
    t = xp.arange(each.shape[1], device=device_of(each))[None, :]
    offset = (t - advanced[:, None]) % period
    allowed = ((offset < window) & (t < period)) | ~synced[:, None]
    return xp.argmin(xp.where(allowed, each, xp.full_like(each, math.inf)), axis=1)


def reference_pose_error(obs: Array, ref: Array, root_scale: float = 1.0) -> Array:
    """(N,) m: the largest distance between simulated and reference disc observations (N, 133) over the
    four end effectors (hands and feet, relative to the root in the heading frame) and the root height
    (times `root_scale`, see `pose_key_error`)."""
    return pose_key_error(pose_keys(obs), pose_keys(ref), root_scale)


def root_height_scale(pose_threshold: float, root_height_threshold: float) -> float:
    """The `root_scale` of `pose_key_error` for reward.root_height_threshold (m): pose_threshold /
    root_height_threshold, so that err > pose_threshold exactly when an end effector is farther than
    pose_threshold or the root height differs by more than root_height_threshold; 1 when it is 0 (off)."""
    if root_height_threshold <= 0 or pose_threshold <= 0:
        return 1.0
    return pose_threshold / root_height_threshold


def yaw_scale(pose_threshold: float, yaw_threshold: float) -> float:
    """The factor (m/rad) that turns reward.yaw_error_threshold's heading error into a pose error:
    pose_threshold / yaw_threshold, so that the scaled error exceeds pose_threshold exactly when the heading
    error exceeds yaw_threshold (rad); 0 when either is 0 (off)."""
    if yaw_threshold <= 0 or pose_threshold <= 0:
        return 0.0
    return pose_threshold / yaw_threshold


def add_yaw_error(
    err: Array,
    yaw_err: Array,
    obs: Array,
    ref: Array,
    ref_active: Array,
    ref_grace: Array,
    has_goal: Array,
    dt: float,
    scale: float,
) -> tuple[Array, Array]:
    """(pose error (N,) m, heading error (N,) rad) after one control step of reward.yaw_error_threshold.

    The heading error is the yaw (rad about +y) the character has gained on its timed reference over
    consecutive counted steps: yaw_err + (w_y - w*_y) dt, with w_y the root's yaw rate in the disc
    observations `obs` and `ref` (N, 133) (rad/s) and `dt` the control step (s). A step counts where the
    reference runs (`ref_active`), out of its grace steps (`ref_grace` == 0) and the commanded skill has no
    heading goal (`has_goal` false: a walk turns to its goal, not with its clip); elsewhere the error
    restarts at 0. A spin left out adds up; one done a moment late does not. The pose error `err` becomes
    max(err, `scale` |yaw_err|) (`yaw_scale`), so one comparison with the pose threshold checks both."""
    xp = namespace(err, obs, ref)
    counted = ref_active & (ref_grace == 0) & ~has_goal
    grown = yaw_err + (obs[:, OBS_YAW_RATE] - ref[:, OBS_YAW_RATE]) * dt
    yaw_err = xp.where(counted, grown, xp.zeros_like(grown))
    return xp.maximum(err, scale * xp.abs(yaw_err)), yaw_err


def goal_features(goal_angle: Array, heading: Array, has_goal: Array) -> Array:
    """(N, 2) state part of the heading goal: (cos, sin) of the goal's world yaw `goal_angle` relative to
    the root's `heading` (radians about +y), zero where the commanded skill has no goal (`has_goal` bool)."""
    xp = namespace(goal_angle, heading)
    rel = goal_angle - heading
    return xp.stack([xp.cos(rel), xp.sin(rel)], axis=1) * xp.astype(has_goal, rel.dtype)[:, None]


def phase_features(frame: Array, clip_frames: Array, shown: Array | None = None) -> Array:
    """(N, 2) (cos, sin) of the clip phase 2 pi frame / (clip_frames - 1) (frames counted from 0); zero
    where `shown` (bool, env.phase_obs: no heading goal and the reference running) is false."""
    xp = namespace(frame, clip_frames)
    phase = 2.0 * math.pi * frame / xp.clip(clip_frames - 1, min=1)
    out = xp.stack([xp.cos(phase), xp.sin(phase)], axis=1)
    return out if shown is None else out * xp.astype(shown, out.dtype)[:, None]


def goal_reward(goal_angle: Array, com_vel: Array, target_speed: Array, has_goal: Array, sharpness: float) -> Array:
    """(N,) heading-goal reward r_G in [0, 1]: exp(-sharpness (v* - d . v_xz)^2) with d the goal's
    horizontal direction (world yaw `goal_angle` radians about +y -> (cos, -sin) in x-z), v the COM
    velocity (m/s) and v* the skill's mean speed (m/s); 1 for skills without a heading goal."""
    xp = namespace(goal_angle, com_vel)
    along = xp.cos(goal_angle) * com_vel[:, 0] - xp.sin(goal_angle) * com_vel[:, 2]
    r = xp.exp(-sharpness * (target_speed - along) ** 2)
    return xp.where(has_goal, r, xp.ones_like(r))


def episode_end(
    fell: Array, unstable: Array, pose_ended: Array, steps: Array, max_steps: int, clip_ended: Array
) -> tuple[Array, Array]:
    """(terminated, truncated) bool masks: a fall (a non-foot body on the ground), a simulator blow-up or a
    large pose error terminates; reaching `max_steps` control steps (`steps` counted after this step) or
    the end of a non-looping reference clip truncates, unless the step also terminated."""
    terminated = fell | unstable | pose_ended
    truncated = ((steps >= max_steps) | clip_ended) & ~terminated
    return terminated, truncated


def advance_reference(frame: Array, loops: Array, clip_frames: Array, restart: bool) -> tuple[Array, Array, Array]:
    """One control step of the timed reference: (new frame, clip ended, restarted), all (N,).

    `frame` the reference clip frame of each env, `loops` whether its clip loops (bool), `clip_frames` its
    length in frames. A looping clip wraps to frame (frame + 1) mod (clip_frames - 1) (its last frame is its
    first). A non-looping clip stops at its last frame and reports `clip ended` (the tracking baseline
    truncates there) or, with `restart` (the pose-error reference and env.phase_obs), starts again at
    frame 0 and reports `restarted` (the caller grants grace steps)."""
    xp = namespace(frame, clip_frames)
    last = xp.clip(clip_frames - 1, min=1)
    nxt = frame + 1
    if restart:
        again = ~loops & (nxt > last)
        new = xp.where(again, xp.zeros_like(nxt), xp.where(loops, nxt % last, nxt))
        return new, xp.zeros_like(again), again
    ended = ~loops & (nxt >= last)
    return xp.where(loops, nxt % last, xp.minimum(nxt, last)), ended, xp.zeros_like(ended)


def update_fall_rates(rates: Array, skill: Array, ended: Array, failed: Array, halflife: float) -> Array:
    """Per-skill exponential moving average of the failure indicator over ended episodes (env.skill_fall_weight).

    `rates` (K,) in [0, 1]; `skill` (N,) each env's command, `ended` (N,) bool its episode ended this step,
    `failed` (N,) bool it ended by a fall or a large pose error. A skill with m ended episodes and f
    failures moves to a^m rates + (1 - a^m) f/m with a = 0.5^(1/halflife): its memory halves every
    `halflife` episodes."""
    xp = namespace(rates, skill)
    of_skill = xp.astype(skill[:, None] == xp.arange(rates.shape[0], device=device_of(skill))[None, :], rates.dtype)
    m = xp.sum(of_skill * xp.astype(ended, rates.dtype)[:, None], axis=0)
    f = xp.sum(of_skill * xp.astype(ended & failed, rates.dtype)[:, None], axis=0)
    keep = 0.5 ** (m / halflife)
    return keep * rates + (1.0 - keep) * (f / xp.maximum(m, xp.ones_like(m)))


def skill_probabilities(rates: Array, fall_weight: float, floor: float = 1e-3) -> Array:
    """(K,) command probabilities: (1 - fall_weight) uniform + fall_weight in proportion to
    `rates` + `floor` (the floor keeps a share for skills that never fall)."""
    xp = namespace(rates)
    w = rates + floor
    return (1.0 - fall_weight) / rates.shape[0] + fall_weight * w / xp.sum(w)


# ---------------------------------------------------------------- per-env bookkeeping
# Commands (eq 4.10: c̄ = (1 - w) c_A + w c_B), the ramp weight w and the timed reference of the pose-error
# check (reward.pose_error_threshold, env.phase_obs): per-env arrays (N,) updated by masks, so the CPU env
# can pass the rows it touches and the device env all N rows with a mask.


def switch_commands(
    cmd: Array, prev_cmd: Array, w: Array, ref_active: Array, mask: Array, new_cmd: Array, ramp_frames: int
) -> tuple[Array, Array, Array, Array, Array]:
    """Command the envs in `mask` ((N,) bool) to `new_cmd` ((N,) skill index): (cmd, prev_cmd, w, ref_active,
    changed), all (N,).

    `cmd` B, `prev_cmd` A, `w` the ramp weight in [0, 1] and `ref_active` whether the timed reference is
    checked. An env whose command changes (`changed`: in `mask` and `new_cmd` != `cmd`) takes the dominant
    command of the blend it leaves (B where w >= 0.5, else A) as its new A, restarts its ramp at w = 0 (w = 1
    at once when `ramp_frames` is 0: no ramp) and suspends its reference until the ramp has ended
    (`restart_after_ramp`). An env in `mask` commanded to its current skill keeps A, w and its reference.
    The caller draws new heading goals where `changed`."""
    xp = namespace(cmd, prev_cmd, w)
    changed = mask & (new_cmd != cmd)
    dominant = xp.where(w >= 0.5, cmd, prev_cmd)
    start = 0.0 if ramp_frames > 0 else 1.0
    return (
        xp.where(mask, new_cmd, cmd),
        xp.where(changed, dominant, prev_cmd),
        xp.where(changed, xp.full_like(w, start), w),
        ref_active & ~changed,
        changed,
    )


def advance_ramp(w: Array, ramp_frames: int) -> Array:
    """(N,) the ramp weight one control step on: w + 1/ramp_frames, at most 1 (eq 4.10's linear ramp over
    `ramp_frames` control frames); 1 everywhere when `ramp_frames` is 0."""
    xp = namespace(w)
    if ramp_frames > 0:
        return xp.minimum(w + 1.0 / ramp_frames, xp.ones_like(w))
    return xp.ones_like(w)


def restart_after_ramp(
    ref_frame: Array, ref_grace: Array, ref_active: Array, w: Array, grace: int
) -> tuple[Array, Array, Array]:
    """(ref_frame, ref_grace, ref_active), all (N,): envs whose reference waits for a command ramp
    (`ref_active` false) and whose ramp has ended (`w` >= 1) start the new clip's reference at frame 0,
    unchecked for `grace` control steps; the others keep theirs."""
    xp = namespace(ref_frame, ref_grace, w)
    start = ~ref_active & (w >= 1.0)
    return (
        xp.where(start, xp.zeros_like(ref_frame), ref_frame),
        xp.where(start, xp.full_like(ref_grace, grace), ref_grace),
        ref_active | start,
    )


def count_down_grace(ref_grace: Array, restarted: Array, grace: int) -> Array:
    """(N,) control steps left without a pose-error check after one step of the timed reference: `grace` where
    the clip has just restarted at frame 0 (`restarted`, from `advance_reference`), else one fewer (not below 0)."""
    xp = namespace(ref_grace, restarted)
    return xp.where(restarted, xp.full_like(ref_grace, grace), xp.maximum(ref_grace - 1, xp.zeros_like(ref_grace)))


def pose_check(
    ref_active: Array, ref_grace: Array, fell: Array, unstable: Array, err: Array, threshold: float
) -> tuple[Array, Array]:
    """(checked, pose_ended) bool (N,): the pose error `err` (N,) m counts where the reference is running
    (`ref_active`), out of its grace steps (`ref_grace` == 0) and the step neither fell nor blew up
    (`checked`); there, an error above `threshold` m ends the episode (`pose_ended`)."""
    checked = ref_active & (ref_grace == 0) & ~(fell | unstable)
    return checked, checked & (err > threshold)


def checked_tracking_reward(obs: Array, scored: Array, checked: Array) -> Array:
    """(N,) reward.w_track's reward: `tracking_reward` of the disc observations `obs` (N, 133) against the
    references the pose error scored them against (`scored` (N, 133)) where `checked` (`pose_check`), else 0."""
    xp = namespace(obs, scored)
    r = tracking_reward(obs, scored)
    return xp.where(checked, r, xp.zeros_like(r))


def reference_check(
    err: Array,
    scored: Array,
    obs: Array,
    ref: Array,
    r_track: Array,
    yaw_err: Array,
    ref_active: Array,
    ref_grace: Array,
    has_goal: Array,
    fell: Array,
    unstable: Array,
    *,
    threshold: float,
    yaw_error_scale: float,
    dt: float,
    reference_reward: bool,
) -> tuple[Array, Array, Array, Array]:
    """One control step's check against the timed reference (reward.pose_error_threshold `threshold` m > 0):
    (r_track, pose_ended, checked, yaw_err), all (N,), what both envs' `step` apply.

    `err` (N,) m the pose error and `scored` (N, 133) the reference observations it was measured against (the
    env's `_pose_error`: the timed reference `ref` (N, 133), or for heading-goal skills their clip's closest
    frame); `obs` (N, 133) the disc observations after the step. With `yaw_error_scale` > 0 (m/rad, `yaw_scale`)
    the heading gained on `ref` over `dt` s joins the error (`add_yaw_error`; `yaw_err` (N,) rad comes back
    updated, else unchanged). `pose_check` then gives `checked` (reference running, out of grace, no fall
    `fell` or blow-up `unstable`) and `pose_ended` (checked and err > threshold). With `reference_reward`
    (reward.w_track) r_track is `checked_tracking_reward` against `scored` (in [0, 1], 0 where unchecked);
    without it the `r_track` passed in (the tracking baseline's, or zeros) comes back."""
    if yaw_error_scale > 0:  # reward.yaw_error_threshold: the heading gained on the reference
        err, yaw_err = add_yaw_error(err, yaw_err, obs, ref, ref_active, ref_grace, has_goal, dt, yaw_error_scale)
    checked, pose_ended = pose_check(ref_active, ref_grace, fell, unstable, err, threshold)
    if reference_reward:  # reward.w_track: the tracking reward where the reference is checked
        r_track = checked_tracking_reward(obs, scored, checked)
    return r_track, pose_ended, checked, yaw_err
