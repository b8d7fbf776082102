"""The web demo (`charctl export RUN --web DIR [--serve]`, docs/web.md) built from the shipped 3-skill policy.

One site is exported through the real CLI with --serve (module fixture) and then checked:
- the files, the MJCF (the run's own physics rate, armature, friction), the served MIME types;
- the ONNX graph, run by onnxruntime-web in Node, against the Python features on recorded simulator
  states: state (243, +2 with env.phase_obs), disc observation, command blend, classifier, PD targets, fall flag;
- Node: the page's simulation module (web/sim.js) runs the policy 10 s from the start state of a
  Python rollout with the same command schedule: body positions agree over the first second, no falls;
- headless Chromium (playwright-core, Debian's chromium): the page loads from the local server with no
  console error and nothing fetched from elsewhere, runs, the character is upright and has moved at
  5 s, a number key changes the command shown.

Needs Node with web/node_modules (`make web-deps`, which `make test` runs) and /usr/bin/chromium for
the browser test (`make web-test-deps`, run by `make test`, installs it with apt-get when root).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from conftest import AMP_RUN, CHARCTL, REPO, assert_one_line_error, cli_env, run_charctl

WEB = REPO / "web"
TESTS_WEB = REPO / "tests" / "web"
RUN = REPO / "pretrained" / "cgail-3skill-fidelity"
CHROMIUM = Path(os.environ.get("CHARCTL_CHROMIUM", "/usr/bin/chromium"))
NODE = shutil.which("node")
SCHEDULE = [(0.0, "walk"), (3.0, "run"), (6.0, "right_kick")]
SECONDS = 10.0
POSITION_TOL_1S = 1e-4  # m, max over bodies and the first 30 control steps (measured: ~3e-7)

pytestmark = pytest.mark.skipif(
    NODE is None or not (WEB / "node_modules" / "@mujoco" / "mujoco").is_dir(),
    reason="the web demo's npm packages are not installed: run `make web-deps` (npm ci in web/; `make test` does)",
)


def node(script: str, *args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    res = subprocess.run(
        [NODE, str(TESTS_WEB / script), *args], capture_output=True, text=True, timeout=timeout, cwd=REPO
    )
    assert res.returncode == 0, f"node {script} failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res


def _serve(run: Path, tmp_path_factory):
    """`charctl export RUN --web DIR --serve` running: yields (site folder, URL, the command's output lines)."""
    site = tmp_path_factory.mktemp("web") / "site"
    exe = [str(CHARCTL)] if CHARCTL.exists() else [sys.executable, "-c", "from charctl.cli import main; main()"]
    proc = subprocess.Popen(
        [*exe, "export", str(run), "--web", str(site), "--serve"],
        cwd=REPO,
        env=cli_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines: list[str] = []
    url = None
    deadline = time.time() + 240
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stdout.readline, "")), daemon=True)
    reader.start()
    while time.time() < deadline and proc.poll() is None:
        hits = [line for line in list(lines) if line.startswith("serving ")]
        if hits:
            url = hits[0].split(" at ", 1)[1].split()[0]
            break
        time.sleep(0.2)
    if url is None:
        proc.kill()
        pytest.fail(f"--serve printed no address: {lines} {proc.stderr.read()[-2000:]}")
    yield site, url, lines
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    """`charctl export pretrained/cgail-3skill-fidelity --web DIR --serve` running: (site folder, URL)."""
    yield from _serve(RUN, tmp_path_factory)


@pytest.fixture(scope="module")
def trained():
    from charctl.experiments.cgail.policy import load_trained_run

    return load_trained_run(RUN)


# ---------------------------------------------------------------------------- the site
def test_export_writes_a_static_site_with_the_runs_mjcf(served, trained):
    import mujoco

    from charctl.experiments.cgail.web_site import PAGE_FILES, VENDOR_FILES
    from charctl.sim.humanoid import build_mjcf, load_model

    site, _, lines = served
    assert lines[0].startswith(f"wrote {site} ("), lines
    for f in (*PAGE_FILES, "model.xml", "policy.onnx", "meta.json", "vendor/LICENSES.txt"):
        assert (site / f).is_file(), f
    for _, _, name in VENDOR_FILES:
        assert (site / "vendor" / name).stat().st_size > 1000, name
    env = trained.cfg.env
    xml = (site / "model.xml").read_text()
    assert xml == build_mjcf(env.physics_hz, 1.0, env.armature)  # the model the run trained on
    ours, theirs = mujoco.MjModel.from_xml_string(xml), load_model(env.physics_hz, 1.0, env.armature)
    assert ours.opt.timestep == theirs.opt.timestep and ours.opt.integrator == theirs.opt.integrator
    assert ours.opt.disableflags == theirs.opt.disableflags  # warm start off, as in training
    np.testing.assert_array_equal(ours.dof_armature, theirs.dof_armature)
    np.testing.assert_array_equal(ours.actuator_gainprm, theirs.actuator_gainprm)
    meta = json.loads((site / "meta.json").read_text())
    assert [s["name"] for s in meta["skills"]] == trained.skill_names == ["walk", "run", "right_kick"]
    assert [s["key"] for s in meta["skills"]] == ["1", "2", "3"]
    assert meta["physics_hz"] == env.physics_hz and meta["control_hz"] == env.control_hz
    assert meta["ramp_frames"] == env.ramp_frames == 60 and meta["state_dim"] == 243 + 2 * env.phase_obs
    assert meta["packages"] == json.loads((WEB / "package.json").read_text())["dependencies"]
    for page in PAGE_FILES:  # the page's own files name nothing outside the site
        text = (site / page).read_text()
        assert "http://" not in text and "https://" not in text and "cdn" not in text.lower(), page


def test_served_with_javascript_and_wasm_types(served):
    _, url, _ = served
    for path, kind in [
        ("", "text/html"),
        ("app.js", "text/javascript"),
        ("vendor/ort.wasm.bundle.min.js", "text/javascript"),
        ("vendor/mujoco.wasm", "application/wasm"),
        ("meta.json", "application/json"),
    ]:
        with urllib.request.urlopen(url + path, timeout=10) as r:
            assert r.status == 200 and r.headers["Content-Type"].startswith(kind), (path, r.headers["Content-Type"])


def test_web_option_errors_are_one_line(tmp_path):
    res = run_charctl("export", str(RUN), "--serve")
    assert_one_line_error(res, "--serve", "--web")
    afile = tmp_path / "afile"
    afile.write_text("x")
    res = run_charctl("export", str(RUN), "--web", str(afile))
    assert_one_line_error(res, "--web", "not a folder")
    assert afile.read_text() == "x"


# ---------------------------------------------------------------------------- the graph vs the Python features
def _record_states(tr, n_envs: int = 12, steps: int = 75, every: int = 3, seed: int = 5):
    """Simulator arrays and the env's own features between control steps: random RSI starts, commands
    switched from outside (as the page does) and, for half the envs, noisy actions so that some fall."""
    from charctl.motion import rotations as R

    env = tr.make_env(n_envs, seed=seed, switch_prob=0.0)
    phase = bool(env.phase_obs)  # the graph's extra `phase` input (web_graph.graph_inputs)
    rng = np.random.default_rng(seed)
    N = env.N
    prev = env.obs.copy()
    latch = (env.cmd.copy(), env.goal_angle.copy())  # what the current state's goal features were built from
    rows: dict[str, list] = {k: [] for k in ("inputs", "state", "obs", "command", "pair", "fell")}
    for t in range(steps):
        if t % 15 == 7:
            ids = np.flatnonzero(rng.random(N) < 0.5)
            env.set_command(ids, rng.integers(0, env.K, len(ids)))
            env.goal_angle[ids] = R.yaw_about_y(env.sim.body_quat_xyzw[ids, 0])  # the page's goal: straight ahead
        s = env.sim
        action = tr.mean_action(env)
        if t % every == 0:
            rows["inputs"].append(
                [
                    np.array(s.xpos),
                    np.array(s.xquat),
                    np.array(s.cvel),
                    np.array(s.subtree_com),
                    np.array(s.geom_xpos),
                    np.array(s.geom_xmat).reshape(N, -1, 9),
                    env.prev_cmd.astype(float),
                    env.cmd.astype(float),
                    env.w.copy(),
                    latch[0].astype(float),
                    latch[1].copy(),
                    prev.copy(),
                    *([env.state[:, -2:].copy()] if phase else []),  # the phase the state carries
                ]
            )
            rows["state"].append(env.state.copy())
            rows["obs"].append(env.obs.copy())
            rows["command"].append(env.command_blend())
            rows["pair"].append(np.concatenate([prev, env.obs], axis=1))
            rows["fell"].append(s.non_foot_ground_contact(env.cfg.fall_tolerance))
        noisy = action + (np.arange(N)[:, None] % 2) * rng.normal(0.0, 0.6, action.shape)
        prev = env.obs.copy()
        res = env.step(noisy)
        done = res.terminated | res.truncated
        prev[done] = env.obs[done]  # a new episode: the classifier's first pair is (o_0, o_0)
        latch = (env.cmd.copy(), env.goal_angle.copy())
    # fallen states never survive a step (the env resets them at once): lower half the characters into the
    # ground by 0.2-0.7 m and record those arrays too, with the env's own features of them
    from charctl.experiments.cgail.features import sim_kinematics

    s = env.sim
    ids = np.arange(0, N, 2)
    qpos = np.array(s.qpos[ids])
    qpos[:, 1] -= rng.uniform(0.2, 0.7, len(ids))
    s.set_state(ids, qpos, np.array(s.qvel[ids]))
    state, obs = env._features(sim_kinematics(s), slice(None))
    rows["inputs"].append(
        [
            np.array(s.xpos),
            np.array(s.xquat),
            np.array(s.cvel),
            np.array(s.subtree_com),
            np.array(s.geom_xpos),
            np.array(s.geom_xmat).reshape(N, -1, 9),
            env.prev_cmd.astype(float),
            env.cmd.astype(float),
            env.w.copy(),
            env.cmd.astype(float),
            env.goal_angle.copy(),
            obs.copy(),
            *([state[:, -2:].copy()] if phase else []),
        ]
    )
    rows["state"].append(state)
    rows["obs"].append(obs)
    rows["command"].append(env.command_blend())
    rows["pair"].append(np.concatenate([obs, obs], axis=1))
    rows["fell"].append(s.non_foot_ground_contact(env.cfg.fall_tolerance))
    cat = {k: np.concatenate(v) for k, v in rows.items() if k != "inputs"}
    # the policy's mean action on each recorded state, as TrainedRun.mean_action computes it
    import torch

    with torch.no_grad():
        mean = tr.agent.model.mean_action(
            torch.as_tensor(cat["state"], dtype=torch.float32), torch.as_tensor(cat["command"], dtype=torch.float32)
        )
    cat["action"] = env.cfg.action_scale * mean.numpy().astype(np.float64)
    inputs = [np.concatenate(parts) for parts in zip(*rows["inputs"])]
    return inputs, cat


def test_onnx_graph_in_onnxruntime_web_equals_the_python_features(served, trained, tmp_path):
    import torch
    import torch.nn.functional as F

    from charctl.experiments.cgail.web_graph import graph_inputs

    site, _, _ = served
    inputs, want = _record_states(trained)
    assert want["fell"].any() and not want["fell"].all(), "the recording should hold standing and fallen states"
    assert (want["command"].max(axis=1) < 1).any(), "the recording should hold ramps between commands"
    names = graph_inputs(trained.cfg.env.phase_obs)
    feeds = {name: {"dims": list(a.shape), "data": a.ravel().tolist()} for name, a in zip(names, inputs, strict=True)}
    (tmp_path / "in.json").write_text(json.dumps(feeds))
    node(
        "graph_eval.mjs", "--site", str(site), "--inputs", str(tmp_path / "in.json"), "--out", str(tmp_path / "o.json")
    )
    out = {k: np.array(v["data"]).reshape(v["dims"]) for k, v in json.loads((tmp_path / "o.json").read_text()).items()}
    B = len(want["state"])
    assert out["state"].shape == (B, trained.agent.model.obs_dim)
    err = {k: float(np.abs(out[k] - want[k]).max()) for k in ("state", "obs", "command")}
    print(f"ONNX graph (onnxruntime-web, Node) vs Python features on {B} recorded states: {err}")
    assert err["state"] < 1e-5 and err["obs"] < 1e-5 and err["command"] < 1e-12, err
    with torch.no_grad():
        # the command blend only selects the style logit (a per-skill style head); the class logits ignore it
        cond = torch.as_tensor(want["command"], dtype=torch.float32)
        _, logits = trained.agent.disc(torch.as_tensor(want["pair"], dtype=torch.float32), cond=cond)
    probs = F.softmax(logits, -1).numpy()
    assert np.abs(out["probs"] - probs).max() < 1e-5
    assert np.abs(out["ctrl"] - want["action"]).max() < 1e-5  # float32 networks: kernels differ in rounding only
    np.testing.assert_array_equal(out["fell"] > 0.5, want["fell"])


# ---------------------------------------------------------------------------- Node: the page's simulation module
def _python_rollout(tr, schedule, seconds):
    """The reference: one env from the evaluation start (clip frame 0, yaw 0), the schedule's switches made
    between steps with the page's goal rule (straight ahead); body positions after every control step, the
    number of terminations, and the state's last two entries before each step up to the first termination
    (the env resets a fallen character, the page does not)."""
    from charctl.motion import rotations as R

    names = tr.skill_names
    env = tr.make_env(1, seed=0, switch_prob=0.0, episode_seconds=1e6)
    env.forced_command = np.array([names.index(schedule[0][1])])
    env.start_frame = 0
    env.random_yaw = False
    env.reset(np.array([0]))
    start = {
        "skill": int(env.cmd[0]),
        "qpos": env.sim.qpos[0].tolist(),
        "qvel": env.sim.qvel[0].tolist(),
        "goal_yaw": float(env.goal_angle[0]),
        "schedule": [[t, names.index(n)] for t, n in schedule],
        "seconds": seconds,
    }
    hz = env.cfg.control_hz
    pending = [(t, names.index(n)) for t, n in schedule[1:]]
    pos, falls, tails = [env.sim.body_pos[0].copy()], 0, []
    for t in range(int(round(seconds * hz))):
        while pending and t / hz >= pending[0][0]:
            _, k = pending.pop(0)
            env.set_command(np.array([0]), k, ramp=True)
            env.forced_command = np.array([k])
            env.goal_angle[0] = R.yaw_about_y(env.sim.body_quat_xyzw[0, 0])
        if falls == 0:
            tails.append(env.state[0, -2:].copy())
        falls += int(env.step(tr.mean_action(env)).terminated[0])
        pos.append(env.sim.body_pos[0].copy())
    return start, np.array(pos), falls, np.array(tails)


def test_node_simulation_module_follows_the_python_rollout(served, trained, tmp_path):
    site, _, _ = served
    start, want, py_falls, _ = _python_rollout(trained, SCHEDULE, SECONDS)
    (tmp_path / "ref.json").write_text(json.dumps(start))
    node(
        "node_rollout.mjs", "--site", str(site), "--ref", str(tmp_path / "ref.json"), "--out", str(tmp_path / "o.json")
    )
    out = json.loads((tmp_path / "o.json").read_text())
    got = np.array(out["positions"])
    assert got.shape == want.shape == (int(SECONDS * 30) + 1, 15, 3)
    err = np.abs(got - want).max(axis=(1, 2))
    first = float(err[:31].max())
    diverge = {tol: next((i / 30 for i, e in enumerate(err) if e > tol), None) for tol in (1e-6, 1e-3, 1e-2)}
    print(
        f"Node vs Python body positions: max {first:.2e} m over the first 1 s, {err[90]:.2e} at 3 s, "
        f"{err[-1]:.2e} at 10 s; first time above 1 um / 1 mm / 1 cm: {diverge}; falls Node {out['falls']}, "
        f"Python {py_falls}; Node {out['inference_ms_per_step']:.2f} ms policy + {out['physics_ms_per_step']:.2f} ms "
        "physics per control step"
    )
    assert first < POSITION_TOL_1S
    assert out["falls"] == 0 and py_falls == 0
    assert min(got[:, 0, 1].min(), want[:, 0, 1].min()) > 0.6  # the pelvis stays up in both
    assert np.linalg.norm(got[-1, 0, [0, 2]]) > 3.0  # and the character went somewhere


# ---------------------------------------------------------------------------- headless Chromium
def _character_pixels(png: Path) -> int:
    """Pixels of the character's right (orange-red) side in a screenshot."""
    import imageio.v3 as iio

    img = iio.imread(png)[..., :3].astype(int)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(((r - g > 40) & (r - b > 60)).sum())


NEEDS_CHROMIUM = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason=f"no Chromium at {CHROMIUM}: `make web-test-deps` installs Debian's chromium (as root, with apt-get)",
)


def _browse(url: str, shots: Path) -> dict:
    """tests/web/browser.mjs on the served page (screenshots and result.json into `shots`): its result, after the
    checks every page must pass (the script finished, no console or page error)."""
    res = node("browser.mjs", "--url", url, "--out", str(shots), "--chromium", str(CHROMIUM), timeout=300)
    r = json.loads((shots / "result.json").read_text())
    assert not r["errors"], r["errors"]
    assert not r["page_error"], r["page_error"]
    assert res.returncode == 0
    return r


@NEEDS_CHROMIUM
def test_page_runs_in_headless_chromium(served, tmp_path):
    site, url, _ = served
    shots = tmp_path / "shots"
    r = _browse(url, shots)
    print(
        f"headless Chromium: load {r.get('load_ms', 0) / 1000:.2f} s ({r.get('load_wall_ms', 0) / 1000:.2f} s from "
        f"navigation), {r.get('fps', 0):.1f} frames/s, real-time factor {r.get('sim_real_time_factor') or 0:.2f}, "
        f"control step {r.get('step_ms') or 0:.1f} ms (median); 5 s of simulation in {r.get('run_wall_s')} s"
    )
    assert all(u.startswith(url) or u.startswith("data:") for u in r["requests"]), r["requests"]
    s0, s5 = r["status_0"], r["status_5"]
    assert s0["time"] == 0 and s0["paused"] and s0["command"] == "walk" and r["command_0"] == "walk"
    assert r["reference_0"] == "none (heading goal)"  # the clip-reference row of a phase_obs run (walk: none)
    assert abs(s5["time"] - 5.0) < 1e-6 and s5["paused"]  # the page paused itself at 5 s for the screenshot
    assert s0["root"][1] > 0.7 and s5["root"][1] > 0.7 and not s5["fallen"] and s5["falls"] == 0
    moved = np.hypot(s5["root"][0] - s0["root"][0], s5["root"][2] - s0["root"][2])
    assert moved > 1.0, f"the character moved only {moved:.2f} m in 5 s"
    assert r["command_after_key"] == "run" and r["status_key"]["command"] == "run"
    assert r["status_after_switch"]["w"] > r["status_key"]["w"] or r["status_after_switch"]["w"] == 1.0  # the ramp runs
    for png in ("page_0s.png", "page_5s.png"):
        assert _character_pixels(shots / png) > 300, f"no character in {png}"
    assert (shots / "page_0s.png").read_bytes() != (shots / "page_5s.png").read_bytes()


@pytest.fixture(scope="module")
def served_amp(tmp_path_factory):
    """The shipped three-skill AMP run's site, served."""
    yield from _serve(AMP_RUN, tmp_path_factory)


@NEEDS_CHROMIUM
def test_amp_page_restarts_in_the_pressed_skill(served_amp, tmp_path):
    """An AMP run has no command input, so its page restarts the character in the pressed skill's clip: 2.5 s
    after key `2` the simulated clock starts near 0 (a conditional run's page goes on from the ~8 s the browser
    script has run by then) and runs on, in the run clip's start state, not fallen."""
    _, url, _ = served_amp
    r = _browse(url, tmp_path / "shots")
    assert r["command_after_key"] == "run"
    after = r["status_after_switch"]
    assert after["command"] == "run" and after["w"] == 1.0  # restarted in the run, no ramp
    # restarted: the clock near 0 just after the key (a conditional page reads the ~8 s it has run), then running
    # on (~2.5 s later; the margins hold on a loaded machine, where the 2.5 s of wall time is slower simulation)
    assert r["status_key"]["time"] < 2.0, r["status_key"]["time"]
    assert r["status_key"]["time"] < after["time"] < r["status_key"]["time"] + 5.0, after["time"]
    assert not after["fallen"] and after["falls"] == 0


# ---------------------------------------------------------------------------- env.phase_obs in the page
PHASE_SCHEDULE = [(0.0, "right_kick"), (0.3, "walk"), (0.5, "right_kick")]


def test_a_phase_obs_run_plays_in_node_with_the_envs_phase(tmp_path):
    """A tiny run trained with env.phase_obs (ramp of 4 frames): exported with --web, its graph takes the
    `phase` input and web/sim.js keeps the reference frame as the env does. Over a kick -> walk -> kick schedule
    the phase in every state Node feeds the graph equals the Python env's, step by step, up to the first
    termination of the Python rollout (the env resets a fallen character, the page does not)."""
    from charctl.experiments.cgail.policy import load_trained_run
    from charctl.experiments.cgail.web_graph import graph_inputs

    root = tmp_path / "runs"
    res = run_charctl(
        "train", "cgail", "scale=smoke", "use_skills=[walk,right_kick]", "env.phase_obs=true", "env.ramp_frames=4",
        f"output_root={root}", timeout=600,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    (run,) = (root / "cgail").iterdir()
    site = tmp_path / "site"
    res = run_charctl("export", str(run), "--web", str(site))
    assert res.returncode == 0, res.stdout + res.stderr
    meta = json.loads((site / "meta.json").read_text())
    assert meta["phase_obs"] is True and [s["loops"] for s in meta["skills"]] == [True, False]
    import onnx

    assert [i.name for i in onnx.load(str(site / "policy.onnx")).graph.input] == list(graph_inputs(True))
    tr = load_trained_run(run)
    assert tr.agent.model.obs_dim == 245
    start, _, _, want = _python_rollout(tr, PHASE_SCHEDULE, 2.0)  # want: the phase before each step
    ref, out = tmp_path / "ref.json", tmp_path / "o.json"
    ref.write_text(json.dumps(start))
    node("node_rollout.mjs", "--site", str(site), "--ref", str(ref), "--out", str(out))
    got = np.array(json.loads(out.read_text())["phases"])[: len(want)]
    print(f"phase compared over {len(want)} control steps; max |Node - Python| {np.abs(got - want).max():.1e}")
    assert len(want) >= 20  # past the first switch (step 9) and the second (15), into the restarted kick
    assert (want[:9, 0] != 0).all() and (want[10:14] == 0).all()  # kick: a phase; walk: none; ramp: none
    np.testing.assert_allclose(got, want, atol=1e-12)
