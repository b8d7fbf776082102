// charctl web demo page: loads the site's files, starts the simulation thread (worker.js, which runs
// sim.js's Character in real time) and draws the character with three.js from the poses it sends.
// Everything it loads is in the site folder (vendor/ holds the pinned npm packages' files); nothing is
// fetched from elsewhere. The page shows, never computes, the policy's quantities: the command blend,
// the classifier's probabilities, r_S and the fall flag come out of policy.onnx.

import * as THREE from './vendor/three.module.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);

// window.charctlDemo: load time, frame counts and the simulation's status, for tests and the curious
const demo = { ready: false, error: null, loadMs: null, frames: 0, renderMs: [], last: null };
window.charctlDemo = demo;
demo.status = () => {
  const s = demo.last;
  if (!s || !demo.meta) return null;
  return { ...s, command: demo.meta.skills[s.skill].name, blend: s.command, fps: state.fps, rtf: state.rtf, quality: demo.quality };
};

const state = { fps: 0, rtf: 0, poses: null };

function fail(err) {
  demo.error = String(err && err.stack ? err.stack : err);
  const box = $('error');
  box.hidden = false;
  box.textContent = `error: ${err && err.message ? err.message : err}`;
  $('loading').hidden = true;
  console.error(err);
}
window.addEventListener('error', (e) => fail(e.error || e.message));
window.addEventListener('unhandledrejection', (e) => fail(e.reason));

// fetch with byte progress over all files together
async function fetchAll(files) {
  const sizes = new Array(files.length).fill(0);
  const totals = new Array(files.length).fill(0);
  const update = () => {
    const total = totals.reduce((a, b) => a + b, 0);
    $('progress').value = total ? sizes.reduce((a, b) => a + b, 0) / total : 0;
  };
  return Promise.all(
    files.map(async (url, i) => {
      const res = await fetch(url);
      if (!res.ok) throw new Error(`cannot load ${url}: HTTP ${res.status}`);
      totals[i] = Number(res.headers.get('content-length')) || 1;
      const reader = res.body.getReader();
      const chunks = [];
      for (;;) {
        const { done, value } = await reader.read();
        if (done) break;
        chunks.push(value);
        sizes[i] += value.length;
        update();
      }
      const out = new Uint8Array(sizes[i]);
      let o = 0;
      for (const c of chunks) {
        out.set(c, o);
        o += c.length;
      }
      return out.buffer;
    }),
  );
}

async function main() {
  const t0 = performance.now();
  const [metaBytes, xmlBytes, onnx, mujocoWasm, ortWasm] = await fetchAll([
    'meta.json',
    'model.xml',
    'policy.onnx',
    'vendor/mujoco.wasm',
    'vendor/ort-wasm-simd-threaded.wasm',
  ]);
  const meta = JSON.parse(new TextDecoder().decode(metaBytes));
  demo.meta = meta;
  const xml = new TextDecoder().decode(xmlBytes);
  const skill = Math.max(0, meta.skills.findIndex((s) => s.name === params.get('skill')));
  const worker = new Worker('worker.js', { type: 'module' });
  demo.worker = worker;
  worker.onerror = (e) => fail(e.message || 'the simulation thread failed to start');
  worker.onmessage = (e) => {
    const msg = e.data;
    if (msg.type === 'error') fail(msg.message);
    else if (msg.type === 'frame') {
      state.poses = msg;
      demo.last = msg.status;
    } else if (msg.type === 'ready') {
      const view = makeView(msg.geoms);
      buildPanel(worker, meta);
      demo.loadMs = performance.now() - t0;
      demo.simLoadMs = msg.loadMs;
      $('load-ms').textContent = `${(demo.loadMs / 1000).toFixed(2)} s`;
      $('loading').hidden = true;
      render(view, meta);
      demo.ready = true;
    }
  };
  worker.postMessage(
    { type: 'init', meta, xml, onnx, mujocoWasm, ortWasm, skill, paused: params.get('paused') === '1' },
    [onnx, mujocoWasm, ortWasm],
  );
}

// ------------------------------------------------------------------ drawing (three.js)
function checkerTexture() {
  const c = document.createElement('canvas');
  c.width = c.height = 128;
  const g = c.getContext('2d');
  g.fillStyle = '#d1d6db';
  g.fillRect(0, 0, 128, 128);
  g.fillStyle = '#adb3bd';
  g.fillRect(0, 0, 64, 64);
  g.fillRect(64, 64, 64, 64);
  const t = new THREE.CanvasTexture(c);
  t.wrapS = t.wrapT = THREE.RepeatWrapping;
  t.colorSpace = THREE.SRGBColorSpace;
  t.anisotropy = 4;
  return t;
}

// software WebGL (SwiftShader, llvmpipe: headless browsers, machines without a GPU) draws every pixel
// on the CPU: there the page draws at half resolution without shadows or antialiasing
// (?quality=high|low and ?scale=F override)
function softwareGL() {
  try {
    const gl = document.createElement('canvas').getContext('webgl2');
    if (!gl) return true;
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    const name = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    gl.getExtension('WEBGL_lose_context')?.loseContext();
    return /swiftshader|llvmpipe|softpipe|software/i.test(String(name));
  } catch {
    return true;
  }
}

function makeView(geoms) {
  const canvas = $('view');
  const quality = params.get('quality') || (softwareGL() ? 'low' : 'high');
  demo.quality = quality;
  const high = quality === 'high';
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: high });
  renderer.setPixelRatio(Number(params.get('scale')) || (high ? Math.min(2, window.devicePixelRatio || 1) : 0.5));
  renderer.shadowMap.enabled = high;
  renderer.shadowMap.type = THREE.PCFShadowMap;
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xcfdff0);
  scene.fog = new THREE.Fog(0xcfdff0, 12, 40);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f96, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 2.2);
  sun.castShadow = high;
  sun.shadow.mapSize.set(1024, 1024);
  const s = 3;
  Object.assign(sun.shadow.camera, { left: -s, right: s, top: s, bottom: -s, near: 0.5, far: 20 });
  scene.add(sun, sun.target);
  const camera = new THREE.PerspectiveCamera(40, 1, 0.05, 100);

  // one mesh per MuJoCo geom, placed every frame from geom_xpos / geom_xmat (world frame, y-up as three.js)
  const meshes = [];
  for (let g = 0; g < geoms.n; g++) {
    const type = geoms.type[g];
    const sz = geoms.size.slice(3 * g, 3 * g + 3);
    const rgba = geoms.rgba.slice(4 * g, 4 * g + 4);
    let geom;
    let mat;
    if (type === 0) {
      // plane: normal +z in the geom frame, like three's PlaneGeometry
      geom = new THREE.PlaneGeometry(2 * sz[0], 2 * sz[1]);
      const tex = checkerTexture();
      tex.repeat.set(sz[0], sz[1]); // 1 m squares
      mat = new THREE.MeshStandardMaterial({ map: tex, roughness: 0.95 });
    } else {
      if (type === 2) geom = new THREE.SphereGeometry(sz[0], 24, 16);
      else if (type === 3) geom = new THREE.CapsuleGeometry(sz[0], 2 * sz[1], 8, 16).rotateX(Math.PI / 2);
      else if (type === 6) geom = new THREE.BoxGeometry(2 * sz[0], 2 * sz[1], 2 * sz[2]);
      else continue;
      mat = new THREE.MeshStandardMaterial({ color: new THREE.Color(rgba[0], rgba[1], rgba[2]), roughness: 0.6, metalness: 0.05 });
    }
    const mesh = new THREE.Mesh(geom, mat);
    mesh.matrixAutoUpdate = false;
    mesh.castShadow = high && type !== 0;
    mesh.receiveShadow = high && type === 0;
    scene.add(mesh);
    meshes.push({ g, mesh });
  }
  const view = { renderer, scene, camera, sun, meshes, target: new THREE.Vector3(), azimuth: 0, first: true };
  if (!high) {
    // without shadows a soft disc under the pelvis keeps the ground contact readable
    const blob = new THREE.Mesh(
      new THREE.CircleGeometry(0.2, 32).rotateX(-Math.PI / 2),
      new THREE.MeshBasicMaterial({ color: 0x000000, transparent: true, opacity: 0.12, depthWrite: false }),
    );
    scene.add(blob);
    view.blob = blob;
  }
  // drag to turn the camera about the character
  let drag = null;
  canvas.addEventListener('pointerdown', (e) => (drag = e.clientX));
  window.addEventListener('pointerup', () => (drag = null));
  window.addEventListener('pointermove', (e) => {
    if (drag === null) return;
    view.azimuth -= (e.clientX - drag) * 0.01;
    drag = e.clientX;
  });
  const resize = () => {
    const w = canvas.clientWidth || window.innerWidth;
    const h = canvas.clientHeight || window.innerHeight;
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    // on a wide window the character sits in the middle of the space right of the panel
    if (w > 800) camera.setViewOffset(w, h, -160, 0, w, h);
    else camera.clearViewOffset();
    camera.updateProjectionMatrix();
  };
  window.addEventListener('resize', resize);
  resize();
  return view;
}

function draw(view, poses, dt) {
  const p = poses.xpos;
  const m = poses.xmat;
  for (const { g, mesh } of view.meshes) {
    const a = 9 * g;
    const b = 3 * g;
    mesh.matrix.set(m[a], m[a + 1], m[a + 2], p[b], m[a + 3], m[a + 4], m[a + 5], p[b + 1], m[a + 6], m[a + 7], m[a + 8], p[b + 2], 0, 0, 0, 1);
    mesh.matrixWorldNeedsUpdate = true;
  }
  // a camera that follows the pelvis (smoothed), from the character's left side at first
  const [x, , z] = poses.status.root;
  // (exponential smoothing with a 0.25 s time constant, never more than 1.5 m behind: also at low frame rates)
  const goal = new THREE.Vector3(x, 0.85, z);
  if (view.first) view.target.copy(goal);
  else view.target.lerp(goal, 1 - Math.exp(-4 * dt));
  const lag = view.target.distanceTo(goal);
  if (lag > 1.5) view.target.lerp(goal, 1 - 1.5 / lag);
  view.first = false;
  const r = 4.2;
  const { camera, target, sun } = view;
  camera.position.set(target.x + r * Math.sin(view.azimuth), target.y + 0.45, target.z + r * Math.cos(view.azimuth));
  camera.lookAt(target.x, target.y - 0.2, target.z);
  if (view.blob) view.blob.position.set(x, 0.002, z);
  sun.position.set(target.x + 2, 6, target.z + 3);
  sun.target.position.copy(target);
  view.renderer.render(view.scene, camera);
}

// ------------------------------------------------------------------ panel
function buildPanel(worker, meta) {
  $('run').textContent = `${meta.label} · ${meta.run}`;
  const skills = $('skills');
  const bars = $('bars');
  bars.innerHTML = '<div class="bar legend"><span></span><span>command c&#772;</span><span>classifier</span></div>';
  // an AMP run (meta.conditional false) has no command input: its skill is picked by the pose it starts in, so a
  // skill button or key restarts the character in that skill's clip instead of ramping a command it cannot see
  const command = (k) => {
    worker.postMessage({ type: 'command', k });
    if (!meta.conditional) worker.postMessage({ type: 'reset' });
  };
  meta.skills.forEach((s, k) => {
    const b = document.createElement('button');
    b.textContent = `${s.key} ${s.name}`;
    b.dataset.skill = String(k);
    b.addEventListener('click', () => command(k));
    skills.appendChild(b);
    const row = document.createElement('div');
    row.className = 'bar';
    row.innerHTML = `<span>${s.name}</span><span class="track"><span class="fill cmd"></span></span><span class="track"><span class="fill prob"></span></span>`;
    bars.appendChild(row);
  });
  $('keys').textContent = meta.skills.map((s) => s.key).filter(Boolean).join(' ');
  const togglePause = () => worker.postMessage({ type: 'pause', paused: !(demo.last && demo.last.paused) });
  const reset = () => worker.postMessage({ type: 'reset' });
  const push = () => worker.postMessage({ type: 'push', force: Number($('push-force').value) });
  $('pause').addEventListener('click', togglePause);
  $('reset').addEventListener('click', reset);
  $('push').addEventListener('click', push);
  window.addEventListener('keydown', (e) => {
    if (e.target && e.target.tagName === 'SELECT') return;
    const k = meta.skills.findIndex((s) => s.key === e.key);
    if (k >= 0) command(k);
    else if (e.key === ' ') togglePause();
    else if (e.key === 'r' || e.key === 'R') reset();
    else if (e.key === 'p' || e.key === 'P') push();
    else return;
    e.preventDefault();
  });
}

// the commanded clip's timed reference as the policy's phase sees it: its frame, or that it waits for a ramp
function referenceText(meta, s) {
  const k = meta.skills[s.skill];
  if (k.heading_goal) return 'none (heading goal)';
  if (!s.refActive) return 'waits for the ramp';
  return `frame ${s.refFrame} of ${k.clip_frames}`;
}

function updatePanel(meta, s) {
  $('command').textContent = meta.skills[s.skill].name;
  $('ramp').textContent = s.w < 1 ? `(from ${meta.skills[s.skillFrom].name}, w = ${s.w.toFixed(2)})` : '';
  $('reference-row').hidden = !meta.phase_obs; // the clip phase in the policy state (env.phase_obs)
  $('reference').textContent = referenceText(meta, s);
  document.querySelectorAll('#skills button').forEach((b) => b.classList.toggle('active', Number(b.dataset.skill) === s.skill));
  if (s.command) {
    document.querySelectorAll('#bars .bar:not(.legend)').forEach((row, k) => {
      row.querySelector('.cmd').style.width = `${(100 * s.command[k]).toFixed(1)}%`;
      row.querySelector('.prob').style.width = meta.conditional ? `${(100 * s.probs[k]).toFixed(1)}%` : '0%';
    });
    $('style').textContent = s.style.toFixed(2);
  }
  $('time').textContent = `${s.time.toFixed(1)} s${s.fallen ? ' (fallen)' : ''}`;
  $('falls').textContent = String(s.falls);
  $('fps').textContent = state.fps ? `${state.fps.toFixed(0)} frames/s` : '-';
  $('step-ms').textContent = `${s.stepMs.toFixed(2)} ms (policy ${s.inferenceMs.toFixed(2)} + physics ${s.physicsMs.toFixed(2)})`;
  $('rtf').textContent = s.paused ? 'paused' : s.simRtf ? `${s.simRtf.toFixed(2)}x` : '-';
  $('pause').textContent = s.paused ? 'resume' : 'pause';
  $('pause').classList.toggle('active', s.paused);
}

// ------------------------------------------------------------------ drawing loop
function render(view, meta) {
  let last = performance.now();
  let windowStart = last;
  let windowFrames = 0;
  let windowSim = null;
  function frame(t) {
    requestAnimationFrame(frame);
    const dt = Math.min(2, Math.max(0, (t - last) / 1000));
    last = t;
    const poses = state.poses;
    if (!poses) return;
    const r0 = performance.now();
    draw(view, poses, dt);
    demo.renderMs.push(performance.now() - r0);
    if (demo.renderMs.length > 600) demo.renderMs.shift();
    demo.frames += 1;
    windowFrames += 1;
    if (windowSim === null) windowSim = poses.status.time;
    if (t - windowStart >= 1000) {
      state.fps = (1000 * windowFrames) / (t - windowStart);
      state.rtf = Math.max(0, (poses.status.time - windowSim) / ((t - windowStart) / 1000));
      windowStart = t;
      windowFrames = 0;
      windowSim = poses.status.time;
    }
    updatePanel(meta, poses.status);
  }
  requestAnimationFrame(frame);
}

main().catch(fail);
