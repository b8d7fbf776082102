"""`charctl export RUN --web DIR [--serve]`: the interactive web demo of a cgail run as a static site.

The site (docs/web.md) runs offline from any static file server: the page (`web/index.html`,
`app.js`, `sim.js`, `style.css` of this repository), the run's MJCF exactly as its environment
compiles it (`model.xml`: physics rate, armature, friction of the run's config), the controller graph
(`policy.onnx`, `web_graph.py`: features, command blend, normaliser, policy, classifier, fall test),
`meta.json` (skills, rates, ramp, start states, push defaults) and, under `vendor/`, the MuJoCo,
onnxruntime-web and three.js files copied from the npm packages pinned in `web/package.json` (installed
by `make web-deps`, i.e. `npm ci` in web/). Nothing is fetched from elsewhere at run time.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError

WEB_SRC = Path(__file__).resolve().parents[3] / "web"
PAGE_FILES = ("index.html", "app.js", "worker.js", "sim.js", "style.css")
# (package, file inside the package, name under vendor/): the single-threaded MuJoCo build (no
# cross-origin isolation needed), onnxruntime-web's WebAssembly-only bundle and its SIMD wasm, three.js
VENDOR_FILES = (
    ("@mujoco/mujoco", "mujoco.js", "mujoco.js"),
    ("@mujoco/mujoco", "mujoco.wasm", "mujoco.wasm"),
    ("onnxruntime-web", "dist/ort.wasm.bundle.min.mjs", "ort.wasm.bundle.min.js"),
    ("onnxruntime-web", "dist/ort-wasm-simd-threaded.wasm", "ort-wasm-simd-threaded.wasm"),
    ("three", "build/three.module.js", "three.module.js"),
    ("three", "build/three.core.js", "three.core.js"),
)
# the srb push study's impulse (docs/srb.md: "an N newton impulse is N newtons held 0.2 s"), from the left
PUSH = {"force_n": 150.0, "duration_s": 0.2, "direction_deg": 90.0}
MIME = {
    ".html": "text/html",
    ".js": "text/javascript",
    ".mjs": "text/javascript",
    ".css": "text/css",
    ".json": "application/json",
    ".wasm": "application/wasm",
    ".onnx": "application/octet-stream",
    ".xml": "application/xml",
    ".png": "image/png",
    ".txt": "text/plain",
}


def pinned_versions(src: Path = WEB_SRC) -> dict[str, str]:
    """{package: version} of web/package.json's dependencies (exact pins)."""
    pkg = json.loads((src / "package.json").read_text())
    return dict(pkg.get("dependencies", {}))


def check_web_sources(src: Path = WEB_SRC) -> None:
    """One-line error unless web/ has the page files and the pinned npm packages installed."""
    if not (src / "package.json").is_file():
        raise CharctlError(
            f"the web demo's sources are not at {src} (they live in the charctl repository's web/ folder); "
            "run charctl from a checkout"
        )
    missing = [f for f in PAGE_FILES if not (src / f).is_file()]
    if missing:
        raise CharctlError(f"the web demo's page files {', '.join(missing)} are missing from {src}")
    for name, want in pinned_versions(src).items():
        meta = src / "node_modules" / name / "package.json"
        if not meta.is_file():
            raise CharctlError(f"npm package {name} is not installed in {src}: run `make web-deps` (npm ci in web/)")
        have = json.loads(meta.read_text()).get("version")
        if have != want:
            raise CharctlError(
                f"npm package {name} in {src} is {have}, web/package.json pins {want}: run `make web-deps`"
            )


def initial_states(tr) -> list[dict]:
    """Per skill, the env's evaluation start (RSI from clip frame 0, at the origin, yaw 0): qpos, qvel."""
    out = []
    for s in tr.agent.skills:
        qpos = np.array(s.qpos[0], dtype=np.float64)
        qpos[[0, 2]] = 0.0  # CgailEnv.reset moves the root to the origin; yaw 0 leaves the rest unchanged
        out.append({"qpos": qpos.tolist(), "qvel": np.asarray(s.qvel[0], dtype=np.float64).tolist()})
    return out


def site_meta(tr, model, checkpoint: str | None) -> dict:
    from charctl.experiments.cgail.features import DISC_OBS_DIM
    from charctl.motion.skeleton import load_skeleton

    skel = load_skeleton()
    env = tr.cfg.env
    keys = [str((i + 1) % 10) for i in range(min(10, len(tr.skill_names)))]
    return {
        "format": 1,
        "run": tr.run_dir.name,
        "checkpoint": checkpoint or "last.pt",
        "label": tr.label,
        "conditional": bool(tr.agent.conditional),
        "skills": [
            {
                "name": s.name,
                "clip": s.clip_name,
                "heading_goal": bool(s.heading_goal),
                "clip_frames": len(s.obs),  # control frames of the clip: the phase's period (env.phase_obs)
                "loops": bool(s.loop),
                "key": keys[i] if i < 10 else "",
            }
            for i, s in enumerate(tr.agent.skills)
        ],
        "physics_hz": float(env.physics_hz),
        "control_hz": float(env.control_hz),
        "armature": float(env.armature),
        "ramp_frames": int(env.ramp_frames),
        "phase_obs": bool(getattr(env, "phase_obs", False)),  # the policy state ends with the clip phase
        "action_scale": float(env.action_scale),
        "fall_tolerance": float(env.fall_tolerance),
        "obs_dim": DISC_OBS_DIM,
        "state_dim": int(tr.agent.model.obs_dim),
        "body_names": list(skel.names),
        "body_ids": [int(model.body(n).id) for n in skel.names],
        "root_body_id": int(model.body(skel.names[0]).id),
        "initial": initial_states(tr),
        "push": dict(PUSH),
        "packages": pinned_versions(),
        "files": {"mjcf": "model.xml", "onnx": "policy.onnx"},
    }


def write_site(tr, out: Path, checkpoint: str | None = None, src: Path = WEB_SRC) -> dict:
    """Write the static site of run `tr` into `out`; returns {files, bytes}."""
    import mujoco

    from charctl.experiments.cgail.web_graph import export_web_onnx
    from charctl.sim.humanoid import build_mjcf

    check_web_sources(src)
    env = tr.cfg.env
    # the MJCF the run's environment compiles (BatchedHumanoid -> load_model(physics_hz, friction 1.0, armature,
    # shoulder_frame))
    xml = build_mjcf(float(env.physics_hz), 1.0, float(env.armature), shoulder_frame=str(env.shoulder_frame))
    model = mujoco.MjModel.from_xml_string(xml)
    out = Path(out)
    (out / "vendor").mkdir(parents=True, exist_ok=True)
    for f in PAGE_FILES:
        shutil.copyfile(src / f, out / f)
    (out / "model.xml").write_text(xml)
    export_web_onnx(tr, model, out / "policy.onnx")
    (out / "meta.json").write_text(json.dumps(site_meta(tr, model, checkpoint), indent=1))
    licences = []
    for pkg, rel, name in VENDOR_FILES:
        root = src / "node_modules" / pkg
        data = (root / rel).read_bytes()
        if name.endswith(".js"):  # the packages' source maps are not shipped: drop the reference
            data = b"\n".join(line for line in data.split(b"\n") if not line.startswith(b"//# sourceMappingURL="))
        (out / "vendor" / name).write_bytes(data)
    for pkg in sorted({p for p, _, _ in VENDOR_FILES}):
        meta = json.loads((src / "node_modules" / pkg / "package.json").read_text())
        licences.append(f"{pkg} {meta.get('version')}: {meta.get('license')} ({meta.get('homepage', '')})")
    (out / "vendor" / "LICENSES.txt").write_text(
        "Files under vendor/ are copied unmodified (source-map comments removed) from these npm packages:\n"
        + "\n".join(licences)
        + "\n"
    )
    files = [p for p in out.rglob("*") if p.is_file()]
    return {"files": len(files), "bytes": sum(p.stat().st_size for p in files)}


def serve(root: Path, port: int = 8000, host: str = "127.0.0.1") -> None:
    """Serve `root` over HTTP (JavaScript, wasm and JSON with their MIME types) until Ctrl-C."""
    import functools
    import http.server

    class Handler(http.server.SimpleHTTPRequestHandler):
        extensions_map = {**http.server.SimpleHTTPRequestHandler.extensions_map, **MIME}

        def log_message(self, format, *args):  # noqa: A002  quiet: one line per request is noise here
            pass

    handler = functools.partial(Handler, directory=str(root))
    server = None
    for p in [port + i for i in range(20)] + [0]:
        try:
            server = http.server.ThreadingHTTPServer((host, p), handler)
            break
        except OSError:
            continue
    if server is None:
        raise CharctlError(f"cannot open a local port on {host} to serve {root}")
    print(f"serving {root} at http://{host}:{server.server_address[1]}/ (Ctrl-C stops)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("stopped")
    finally:
        server.server_close()
