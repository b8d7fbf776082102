// Shared by the Node tests: load MuJoCo (WebAssembly) and onnxruntime-web from web/node_modules (the
// packages the site vendors, same pinned versions), and a site's files, then build sim.js's Character.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

export const REPO = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..', '..');
export const WEB = path.join(REPO, 'web');
const MODULES = path.join(WEB, 'node_modules');

export async function loadRuntimes() {
  const { default: loadMujoco } = await import(pathToFileURL(path.join(MODULES, '@mujoco/mujoco/mujoco.js')).href);
  const ort = await import(pathToFileURL(path.join(MODULES, 'onnxruntime-web/dist/ort.node.min.mjs')).href);
  ort.env.wasm.numThreads = 1; // as on the page
  ort.env.logLevel = 'error';
  const mujoco = await loadMujoco();
  return { mujoco, ort };
}

export function readSite(site) {
  return {
    meta: JSON.parse(fs.readFileSync(path.join(site, 'meta.json'), 'utf8')),
    xml: fs.readFileSync(path.join(site, 'model.xml'), 'utf8'),
    onnx: new Uint8Array(fs.readFileSync(path.join(site, 'policy.onnx'))),
  };
}

export async function makeCharacter(site) {
  const { mujoco, ort } = await loadRuntimes();
  const { Character } = await import(pathToFileURL(path.join(WEB, 'sim.js')).href);
  const { meta, xml, onnx } = readSite(site);
  const sim = await Character.create({ mujoco, ort, xml, onnx, meta });
  return { sim, mujoco, ort, meta, onnx };
}

export function args() {
  const out = {};
  const a = process.argv.slice(2);
  for (let i = 0; i < a.length; i += 2) out[a[i].replace(/^--/, '')] = a[i + 1];
  return out;
}
