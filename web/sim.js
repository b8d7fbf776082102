// charctl web demo: one simulated character driven by the exported cgail graph (docs/web.md).
//
// Used by the page (app.js) and by the Node tests (tests/web/*.mjs): it is given the MuJoCo module
// (@mujoco/mujoco), onnxruntime-web, the site's MJCF text, ONNX bytes and meta.json, and knows nothing
// of the browser. Per control step it copies MuJoCo's arrays into the ONNX graph, which computes the
// policy state, the command blend, the normaliser, the policy, the classifier and the fall test in the
// project's own torch code (charctl/experiments/cgail/web_graph.py); the PD targets it returns are
// written to data.ctrl and held for physics_hz / control_hz MuJoCo steps. No feature is computed here.
//
// Units: seconds, radians (yaw about world +y), newtons; world y-up, as in charctl.

export const GRAPH_INPUTS = [
  'xpos', 'xquat', 'cvel', 'subtree_com', 'geom_xpos', 'geom_xmat',
  'skill_from', 'skill_to', 'ramp_w', 'goal_skill', 'goal_yaw', 'prev_obs',
]; // plus 'phase' for a run trained with env.phase_obs (meta.phase_obs)

// heading (yaw about +y) of a wxyz quaternion's forward (+x) axis: atan2(-f_z, f_x), as charctl's
// rotations.yaw_about_y. Used only to aim pushes and goals, never as a policy input.
export function yawOfQuat(w, x, y, z) {
  const fx = 1 - 2 * (y * y + z * z);
  const fz = 2 * (x * z - y * w);
  return Math.atan2(-fz, fx);
}

export class Character {
  // mujoco: the loaded MuJoCo module; ort: onnxruntime-web; xml: MJCF text; onnx: Uint8Array of the
  // graph; meta: the site's meta.json (skills, rates, initial states, push defaults)
  static async create({ mujoco, ort, xml, onnx, meta, sessionOptions }) {
    const session = await ort.InferenceSession.create(onnx, {
      executionProviders: ['wasm'],
      graphOptimizationLevel: 'all',
      ...(sessionOptions || {}),
    });
    return new Character(mujoco, ort, xml, session, meta);
  }

  constructor(mujoco, ort, xml, session, meta) {
    this.mujoco = mujoco;
    this.ort = ort;
    this.session = session;
    this.meta = meta;
    this.model = mujoco.MjModel.from_xml_string(xml);
    this.data = new mujoco.MjData(this.model);
    const m = this.model;
    this.nbody = m.nbody;
    this.ngeom = m.ngeom;
    this.substeps = Math.round(meta.physics_hz / meta.control_hz);
    if (Math.abs(m.opt.timestep * meta.physics_hz - 1) > 1e-5) { // the MJCF writes the step to 8 decimals
      throw new Error(`MJCF timestep ${m.opt.timestep} is not 1/${meta.physics_hz}`);
    }
    this.controlDt = 1 / meta.control_hz;
    this.rampFrames = meta.ramp_frames;
    this.K = meta.skills.length;
    this.rootBody = meta.root_body_id;
    this.bodyIds = meta.body_ids; // charctl body order -> MuJoCo body ids
    // env.phase_obs: the policy state ends with (cos, sin) of the commanded clip's timed reference frame,
    // kept here as charctl's env keeps it (CgailEnv._advance_phase, _restart_reference_after_ramp)
    this.phaseObs = Boolean(meta.phase_obs);
    this.clipFrames = meta.skills.map((s) => s.clip_frames ?? 1);
    this.clipLoops = meta.skills.map((s) => Boolean(s.loops));
    this.hasGoal = meta.skills.map((s) => Boolean(s.heading_goal));
    this.falls = 0;
    this.fallen = false;
    this.steps = 0;
    this.time = 0;
    this.pushes = [];
    this.last = null; // outputs of the latest graph evaluation
    this.lastInferenceMs = 0;
    this.lastPhysicsMs = 0;
    this.reset(0);
  }

  // Start pose of skill k (frame 0 of its clip, at the origin, heading +x) or the given qpos/qvel;
  // the command is k with no ramp and the heading goal straight ahead (or goalYaw).
  // `frame`: the clip frame the state is taken from (the reference's start; 0 for the initial state).
  reset(k, { qpos, qvel, goalYaw, frame = 0 } = {}) {
    const { mujoco, model, data } = this;
    const init = this.meta.initial[k];
    mujoco.mj_resetData(model, data);
    data.qpos.set(qpos || init.qpos);
    data.qvel.set(qvel || init.qvel);
    data.ctrl.set(data.qpos.subarray(7, 7 + model.nu));
    data.xfrc_applied.fill(0);
    mujoco.mj_forward(model, data);
    this.skillFrom = k;
    this.skillTo = k;
    this.w = 1;
    const q = data.xquat;
    const r = this.rootBody * 4;
    this.goalYaw = goalYaw ?? yawOfQuat(q[r], q[r + 1], q[r + 2], q[r + 3]);
    // the goal the next state carries (latched: see step())
    this.stateGoalSkill = k;
    this.stateGoalYaw = this.goalYaw;
    this.prevObs = null; // the first classifier pair is (o_0, o_0)
    this.refFrame = frame;
    this.refActive = true;
    this.statePhase = this._phase(); // the phase the next state carries (latched, as the goal)
    this.pushes = [];
    this.fallen = false;
    this.fallTime = null;
    this.time = 0;
    this.steps = 0;
    this.last = null;
  }

  // Switch the command to k with the training ramp (env.set_command): the blend goes from the
  // dominant command of the current blend to k over ramp_frames control steps.
  setCommand(k, { ramp = true } = {}) {
    if (k === this.skillTo || k < 0 || k >= this.K) return;
    const dominant = this.w >= 0.5 ? this.skillTo : this.skillFrom;
    this.skillFrom = dominant;
    this.skillTo = k;
    this.w = ramp && this.rampFrames > 0 ? 0 : 1;
    this.refActive = false; // the new clip's reference starts at frame 0 once the ramp has ended
    const q = this.data.xquat;
    const r = this.rootBody * 4;
    this.goalYaw = yawOfQuat(q[r], q[r + 1], q[r + 2], q[r + 3]); // new goal: straight ahead
  }

  // A horizontal force of `force` newtons on the pelvis for `seconds`, in the heading-frame direction
  // `directionDeg` at onset (0 forward, 90 left): the srb push study's impulse (100 N held 0.2 s = 20 N s).
  push(force = this.meta.push.force_n, directionDeg = this.meta.push.direction_deg, seconds = this.meta.push.duration_s) {
    const q = this.data.xquat;
    const r = this.rootBody * 4;
    const a = yawOfQuat(q[r], q[r + 1], q[r + 2], q[r + 3]) + (directionDeg * Math.PI) / 180;
    const substeps = Math.max(1, Math.round(seconds * this.meta.physics_hz));
    this.pushes.push({ fx: force * Math.cos(a), fz: -force * Math.sin(a), left: substeps });
  }

  _inputs() {
    const { ort, data, nbody, ngeom } = this;
    const T = (arr, dims) => new ort.Tensor('float64', Float64Array.from(arr), dims);
    const S = (v) => new ort.Tensor('float64', Float64Array.of(v), [1]);
    return {
      xpos: T(data.xpos, [1, nbody, 3]),
      xquat: T(data.xquat, [1, nbody, 4]),
      cvel: T(data.cvel, [1, nbody, 6]),
      subtree_com: T(data.subtree_com, [1, nbody, 3]),
      geom_xpos: T(data.geom_xpos, [1, ngeom, 3]),
      geom_xmat: T(data.geom_xmat, [1, ngeom, 9]),
      skill_from: S(this.skillFrom),
      skill_to: S(this.skillTo),
      ramp_w: S(this.w),
      goal_skill: S(this.stateGoalSkill),
      goal_yaw: S(this.stateGoalYaw),
      prev_obs: new ort.Tensor('float64', this.prevObs || new Float64Array(this.meta.obs_dim), [1, this.meta.obs_dim]),
      ...(this.phaseObs ? { phase: new ort.Tensor('float64', Float64Array.from(this.statePhase), [1, 2]) } : {}),
    };
  }

  // (cos, sin) of the reference frame's phase of the current command; (0, 0) for a skill with a heading
  // goal and while the reference waits for a ramp (env._phase_features); null without env.phase_obs
  _phase() {
    if (!this.phaseObs) return null;
    const k = this.skillTo;
    if (this.hasGoal[k] || !this.refActive) return [0, 0];
    const a = (2 * Math.PI * this.refFrame) / Math.max(this.clipFrames[k] - 1, 1);
    return [Math.cos(a), Math.sin(a)];
  }

  // One frame on (env._advance_phase with restart): a looping clip wraps, a non-looping one starts again at 0
  _advancePhase() {
    const k = this.skillTo;
    const last = Math.max(this.clipFrames[k] - 1, 1);
    const next = this.refFrame + 1;
    this.refFrame = this.clipLoops[k] ? next % last : next > last ? 0 : next;
  }

  // Evaluate the graph on the current state (no stepping); the first call after a reset uses o_0 as
  // its own predecessor for the classifier.
  async evaluate() {
    if (this.prevObs === null) {
      const out0 = await this.session.run(this._inputs());
      this.prevObs = Float64Array.from(out0.obs.data);
    }
    const out = await this.session.run(this._inputs());
    const get = (name) => Float64Array.from(out[name].data);
    this.last = {
      ctrl: get('ctrl'),
      state: get('state'),
      command: get('command'),
      obs: get('obs'),
      probs: get('probs'),
      style: out.style.data[0],
      fell: out.fell.data[0] > 0.5,
    };
    return this.last;
  }

  // One control step: graph -> PD targets -> substeps physics steps (pushes applied per substep) ->
  // positions and velocities brought up to date (as charctl's batch at mjSTAGE_VEL) -> ramp advanced.
  // Returns the graph's outputs for the state the step started from.
  async step() {
    const { mujoco, model, data } = this;
    const t0 = now();
    const out = await this.evaluate();
    const t1 = now();
    if (out.fell && !this.fallen) {
      this.falls += 1;
      this.fallen = true;
      this.fallTime = this.time;
    }
    data.ctrl.set(out.ctrl);
    const xfrc = data.xfrc_applied;
    const base = this.rootBody * 6;
    for (let i = 0; i < this.substeps; i++) {
      xfrc.fill(0);
      for (const p of this.pushes) {
        if (p.left > 0) {
          xfrc[base] += p.fx;
          xfrc[base + 2] += p.fz;
          p.left -= 1;
        }
      }
      mujoco.mj_step(model, data);
    }
    xfrc.fill(0);
    this.pushes = this.pushes.filter((p) => p.left > 0);
    mujoco.mj_fwdPosition(model, data);
    mujoco.mj_fwdVelocity(model, data);
    this.lastInferenceMs = t1 - t0;
    this.lastPhysicsMs = now() - t1;
    // charctl's env computes s_t+1 at the end of this step, before a switch made between steps takes
    // effect: the next state carries the command and goal as they are now (web_graph.py, goal_skill)
    this.stateGoalSkill = this.skillTo;
    this.stateGoalYaw = this.goalYaw;
    this._advancePhase();
    this.statePhase = this._phase();
    this.prevObs = out.obs;
    if (this.rampFrames > 0) this.w = Math.min(1, this.w + 1 / this.rampFrames);
    else this.w = 1;
    if (!this.refActive && this.w >= 1) {
      this.refFrame = 0;
      this.refActive = true;
    }
    this.steps += 1;
    this.time = this.steps * this.controlDt;
    if (!isFiniteArray(data.qpos) || !isFiniteArray(data.qvel)) {
      this.falls += this.fallen ? 0 : 1;
      this.reset(this.skillTo);
    }
    return out;
  }

  // (15, 3) world positions of the body frames in charctl's body order (root first)
  bodyPositions() {
    const x = this.data.xpos;
    return this.bodyIds.map((b) => [x[3 * b], x[3 * b + 1], x[3 * b + 2]]);
  }

  rootPosition() {
    const x = this.data.xpos;
    const b = this.rootBody * 3;
    return [x[b], x[b + 1], x[b + 2]];
  }

  dispose() {
    this.data.delete();
    this.model.delete();
  }
}

function isFiniteArray(a) {
  for (let i = 0; i < a.length; i++) if (!Number.isFinite(a[i])) return false;
  return true;
}

function now() {
  return globalThis.performance ? globalThis.performance.now() : Date.now();
}
