// Node test (tests/test_web.py): evaluate a site's policy.onnx with onnxruntime-web (the runtime the
// page uses) on a batch of recorded simulator arrays; writes every output.
//   node graph_eval.mjs --site DIR --inputs in.json --out out.json
// in.json: {name: {dims: [...], data: [...]}} for every graph input (float64)
import fs from 'node:fs';
import { args, loadRuntimes, readSite } from './common.mjs';

const a = args();
const { ort } = await loadRuntimes();
const { onnx } = readSite(a.site);
const session = await ort.InferenceSession.create(onnx, { executionProviders: ['wasm'] });
const inputs = JSON.parse(fs.readFileSync(a.inputs, 'utf8'));
const feeds = {};
for (const [name, { dims, data }] of Object.entries(inputs)) feeds[name] = new ort.Tensor('float64', Float64Array.from(data), dims);
const out = await session.run(feeds);
const result = {};
for (const name of session.outputNames) result[name] = { dims: out[name].dims, data: Array.from(out[name].data) };
fs.writeFileSync(a.out, JSON.stringify(result));
