// charctl web demo: the simulation thread. Runs sim.js's Character against the wall clock in a Web
// Worker, so that drawing (which can be slow: software WebGL) never slows the simulation down. The page
// (app.js) sends the site's files and the user's actions; this thread answers with the geoms' poses and
// what the panel shows after every burst of control steps.
//
// messages in:  {type: 'init', meta, xml, onnx, mujocoWasm, ortWasm, skill}, {type: 'command', k},
//               {type: 'reset'}, {type: 'push', force}, {type: 'pause', paused}, {type: 'pause_at', time}
//               (pause when the simulated time reaches `time` seconds: exact screenshots in tests)
// messages out: {type: 'ready', geoms, loadMs}, {type: 'frame', xpos, xmat, status}, {type: 'error', message}

import * as ort from './vendor/ort.wasm.bundle.min.js';
import loadMujoco from './vendor/mujoco.js';
import { Character } from './sim.js';

const FALL_RESET_S = 2.0; // a fallen character restarts after this many simulated seconds
let sim = null;
const queue = [];
let paused = false;
let pauseAt = null;
let pending = 0;
let stepMs = 0;
const stepTimes = [];
// simulated seconds per wall-clock second over the last 2 s of running (not paused)
const clock = { wall: 0, sim: 0, samples: [], rtf: null };

function fail(err) {
  postMessage({ type: 'error', message: String(err && err.stack ? err.stack : err) });
}

async function init(msg) {
  const t0 = performance.now();
  ort.env.wasm.numThreads = 1; // no cross-origin isolation needed: any static server works
  ort.env.wasm.proxy = false;
  ort.env.wasm.wasmBinary = msg.ortWasm;
  ort.env.logLevel = 'error';
  const mujoco = await loadMujoco({ wasmBinary: msg.mujocoWasm });
  sim = await Character.create({ mujoco, ort, xml: msg.xml, onnx: new Uint8Array(msg.onnx), meta: msg.meta });
  sim.reset(msg.skill);
  await sim.evaluate();
  const m = sim.model;
  postMessage({
    type: 'ready',
    loadMs: performance.now() - t0,
    geoms: {
      n: m.ngeom,
      type: Array.from(m.geom_type),
      size: Array.from(m.geom_size),
      rgba: Array.from(m.geom_rgba),
    },
  });
  paused = !!msg.paused;
  send();
  loop();
}

function status() {
  const out = sim.last;
  return {
    time: sim.time,
    skill: sim.skillTo,
    skillFrom: sim.skillFrom,
    w: sim.w,
    refFrame: sim.refFrame,
    refActive: sim.refActive,
    falls: sim.falls,
    fallen: sim.fallen,
    root: sim.rootPosition(),
    command: out ? Array.from(out.command) : null,
    probs: out ? Array.from(out.probs) : null,
    style: out ? out.style : null,
    stepMs,
    stepMsMedian: median(stepTimes),
    simRtf: clock.rtf,
    inferenceMs: sim.lastInferenceMs,
    physicsMs: sim.lastPhysicsMs,
    paused,
  };
}

function median(a) {
  if (!a.length) return null;
  const s = a.slice().sort((x, y) => x - y);
  return s[Math.floor(s.length / 2)];
}

function send() {
  postMessage({
    type: 'frame',
    xpos: Float64Array.from(sim.data.geom_xpos),
    xmat: Float64Array.from(sim.data.geom_xmat),
    status: status(),
  });
}

// user actions run between control steps, in order
async function applyQueued() {
  while (queue.length) {
    const a = queue.shift();
    if (a.type === 'command') sim.setCommand(a.k);
    else if (a.type === 'push') sim.push(a.force);
    else if (a.type === 'pause') paused = a.paused;
    else if (a.type === 'pause_at') pauseAt = a.time;
    else if (a.type === 'reset') {
      sim.reset(sim.skillTo);
      pending = 0;
      await sim.evaluate();
    }
  }
}

// Control steps owed to the wall clock run in bursts of at most 50 ms; a backlog beyond 0.25 s is
// dropped (that machine runs below real time, and the page says so).
function loop() {
  const dtc = sim.controlDt;
  let lastTick = performance.now();
  async function tick() {
    const t = performance.now();
    if (!paused) {
      pending += Math.min(0.25, (t - lastTick) / 1000);
      clock.wall += (t - lastTick) / 1000;
      clock.samples.push([clock.wall, clock.sim]);
      while (clock.samples.length > 2 && clock.wall - clock.samples[0][0] > 2) clock.samples.shift();
      const [w0, s0] = clock.samples[0];
      if (clock.wall - w0 > 0.5) clock.rtf = (clock.sim - s0) / (clock.wall - w0);
    }
    lastTick = t;
    let stepped = queue.length > 0;
    try {
      await applyQueued();
      for (;;) {
        if (pauseAt !== null && sim.time >= pauseAt - 1e-9) {
          paused = true;
          pauseAt = null;
          pending = 0;
          stepped = true;
        }
        if (paused || pending < dtc || performance.now() - t >= 50) break;
        const s0 = performance.now();
        await sim.step();
        stepMs = performance.now() - s0;
        stepTimes.push(stepMs);
        if (stepTimes.length > 300) stepTimes.shift();
        pending -= dtc;
        clock.sim += dtc;
        stepped = true;
        if (sim.fallen && sim.time - sim.fallTime > FALL_RESET_S) {
          sim.reset(sim.skillTo);
          await sim.evaluate();
        }
        await applyQueued();
      }
      if (pending > 0.25) pending = 0;
      if (stepped) send();
    } catch (e) {
      fail(e);
      return;
    }
    const wait = queue.length ? 0 : Math.max(0, (dtc - pending) * 1000 - (performance.now() - lastTick));
    setTimeout(tick, Math.min(wait, 50));
  }
  setTimeout(tick, 0);
}

onmessage = (e) => {
  const msg = e.data;
  if (msg.type === 'init') init(msg).catch(fail);
  else queue.push(msg);
};
self.addEventListener('unhandledrejection', (e) => fail(e.reason));
