// Node test (tests/test_web.py): the page's simulation module runs the exported policy from a given
// start state with a command schedule and records the body positions after every control step.
//   node node_rollout.mjs --site DIR --ref ref.json --out out.json
// ref.json: {skill, qpos, qvel, goal_yaw, schedule: [[seconds, skill], ...], seconds}
import fs from 'node:fs';
import { args, makeCharacter } from './common.mjs';

const a = args();
const ref = JSON.parse(fs.readFileSync(a.ref, 'utf8'));
const t0 = performance.now();
const { sim, meta } = await makeCharacter(a.site);
const tLoad = performance.now() - t0;
sim.reset(ref.skill, { qpos: ref.qpos, qvel: ref.qvel, goalYaw: ref.goal_yaw });
const pending = ref.schedule.slice(1);
const steps = Math.round(ref.seconds * meta.control_hz);
const positions = [sim.bodyPositions()];
const states = [];
const phases = []; // (cos, sin) at the end of the state each step started from (runs with meta.phase_obs)
let inferMs = 0;
let physicsMs = 0;
const t1 = performance.now();
for (let t = 0; t < steps; t++) {
  while (pending.length && t / meta.control_hz >= pending[0][0]) {
    sim.setCommand(pending.shift()[1]);
  }
  const out = await sim.step();
  inferMs += sim.lastInferenceMs;
  physicsMs += sim.lastPhysicsMs;
  if (t < 3) states.push(Array.from(out.state));
  if (meta.phase_obs) phases.push(Array.from(out.state.slice(-2)));
  positions.push(sim.bodyPositions());
}
const wall = performance.now() - t1;
fs.writeFileSync(
  a.out,
  JSON.stringify({
    positions,
    states,
    phases,
    falls: sim.falls,
    steps,
    load_ms: tLoad,
    wall_ms: wall,
    inference_ms_per_step: inferMs / steps,
    physics_ms_per_step: physicsMs / steps,
  }),
);
sim.dispose();
