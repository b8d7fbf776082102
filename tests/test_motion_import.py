"""`charctl data import`: mocap files of other skeletons retargeted onto the humanoid (issue 27).

Real files (tests/data/README.md: sources and licenses) of four skeleton conventions meet the issue's
targets; hand-built cases check the geometry (a turned, Z-up, centimetre copy of a DeepMimic clip comes
back to itself), the detection of up axis and units and the flags that override them; bad files and bad
maps are one-line errors with nothing written; the imported clip is accepted wherever a clip name goes.
The slow tier adds the PD tracking check per file, the DeepMimic reference it is compared with, the import
speed, and a small end-to-end training run on an imported walk.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from charctl.errors import CharctlError

from conftest import REPO, assert_one_line, assert_one_line_error, charctl_in_process, run_charctl

DATA = REPO / "tests" / "data"
# file -> (skeleton map detected, up axis, units) ; every file is real motion capture (tests/data/README.md)
REAL = {
    "cmu_walk.bvh": ("cmu", "y", "cmu"),
    "cmu3dsmax_131_01_walk.bvh": ("biovision", "y", "m"),
    "optitrack_arena_louise.bvh": ("biovision", "y", "cm"),
    "bandai_namco_walk.bvh": ("unity", "y", "cm"),
}


@pytest.fixture(scope="module")
def imported():
    """Each real file retargeted once (the module's tests share them)."""
    from charctl.motion.retarget import retarget

    return {name: retarget(DATA / name) for name in REAL}


# ---------------------------------------------------------------------------- real files
def test_the_test_files_are_small_and_documented():
    readme = (DATA / "README.md").read_text()
    for name in REAL:
        assert (DATA / name).stat().st_size < 300_000, name
        assert name in readme, f"{name} has no source/license entry in tests/data/README.md"
    assert "license" in readme.lower()


@pytest.mark.parametrize("name", sorted(REAL))
def test_real_file_is_detected_and_meets_the_targets(name, imported):
    from charctl.motion import import_report as rep

    r = imported[name]
    skeleton, up, units = REAL[name]
    assert (r.source.jmap.name, r.source.up, r.source.units) == (skeleton, up, units)
    q = rep.measure(r)
    assert max(q.ee_error_max_cm.values()) <= rep.EE_TARGET_CM, q.ee_error_max_cm
    assert max(q.slide_max_cm.values()) <= rep.SLIDE_TARGET_CM, q.slide_max_cm
    assert q.penetration_max_cm <= rep.PENETRATION_TARGET_CM, (q.penetration_max_cm, q.penetration_body)
    assert q.limit_violation_frames == 0, q.limit_violation_max_deg
    assert abs(r.clip.fps - 60.0) < 0.5 and r.clip.num_frames >= 100
    assert np.all(np.isfinite(r.clip.local_rot)) and np.allclose(np.linalg.norm(r.clip.local_rot, axis=-1), 1.0)
    # frame 0 at the origin facing +x, standing: the pelvis at a human height
    assert np.allclose(r.clip.root_pos[0, [0, 2]], 0.0, atol=1e-9) and abs(r.clip.heading()[0]) < 1e-6
    assert 0.6 < np.median(r.clip.root_pos[:, 1]) < 1.0


def test_walks_go_forward_with_alternating_stance(imported):
    for name in ("cmu_walk.bvh", "bandai_namco_walk.bvh"):
        r = imported[name]
        travel = r.clip.root_pos[-1, 0] - r.clip.root_pos[0, 0]
        speed = travel / r.clip.duration
        assert 0.6 < speed < 2.0, (name, speed)
        share = r.contacts.mean(axis=0)
        assert np.all((share > 0.25) & (share < 0.8)), (name, share)
        assert not np.all(r.contacts, axis=1).all()  # not both feet down the whole time


def test_cmu_reference_tpose_frame_is_left_out(imported):
    r = imported["cmu_walk.bvh"]
    assert r.source.dropped_frames == 1  # the CMU conversions start with a T-pose frame
    assert r.source.frames_in_file == 344


def test_filmstrip_and_report_are_written(imported, tmp_path):
    from charctl.motion import import_report as rep

    r = imported["bandai_namco_walk.bvh"]
    q = rep.measure(r)
    film = rep.write_filmstrip(r, tmp_path / "f.png", n=4)
    md = rep.write_report(r, q, tmp_path / "x.txt", tmp_path / "x.report.md", film, 1.0)
    assert film.stat().st_size > 10_000
    text = md.read_text()
    assert "unity" in text and "| end-effector error" in text and "f.png" in text


# ---------------------------------------------------------------------------- hand-built cases
def _turned_copy(clip, path: Path, yaw: float = 0.7, scale: float = 100.0, z_up: bool = True) -> Path:
    """The clip as a BVH with the humanoid's joint names, turned by `yaw`, made Z-up and in centimetres."""
    from charctl.motion import rotations as R
    from charctl.motion.bvh import write_bvh

    q = R.heading_quat(np.array(yaw))
    if z_up:  # +y -> +z
        q = R.multiply(R.from_axis_angle(np.array([1.0, 0.0, 0.0]), np.array(np.pi / 2)), q)
    T = clip.num_frames
    rot = clip.local_rot.copy()
    rot[:, 0] = R.multiply(np.broadcast_to(q, (T, 4)), rot[:, 0])
    write_bvh(clip.replace(root_pos=R.rotate(np.broadcast_to(q, (T, 4)), clip.root_pos), local_rot=rot), path)
    lines, out, motion = path.read_text().splitlines(), [], False
    for line in lines:
        s = line.strip()
        if s.startswith("OFFSET"):
            v = [float(x) * scale for x in s.split()[1:]]
            line = line[: len(line) - len(line.lstrip())] + "OFFSET " + " ".join(f"{x:.6f}" for x in v)
        elif motion:
            v = s.split()
            v[:3] = [f"{float(x) * scale:.6f}" for x in v[:3]]
            line = " ".join(v)
        elif s.startswith("Frame Time"):
            motion = True
        out.append(line)
    path.write_text("\n".join(out) + "\n")
    return path


@pytest.mark.parametrize("name", ["walk", "run", "jump", "kick"])
def test_turned_zup_centimetre_copy_of_a_deepmimic_clip_comes_back_within_1cm(name, tmp_path):
    from charctl.motion.library import load_clip
    from charctl.motion.retarget import retarget

    clip = load_clip(name).resample(60.0)
    path = _turned_copy(clip, tmp_path / "copy.bvh")
    r = retarget(path, fps=60.0, ground=False)  # the geometry alone: the clip's own feet kept as they are
    assert (r.source.jmap.name, r.source.up, r.source.units) == ("charctl", "z", "cm")
    assert abs(r.scale - 1.0) < 1e-4
    ref = clip.canonicalize(0)
    err = np.linalg.norm(r.clip.body_pos - ref.body_pos, axis=-1)
    assert err.max() < 0.01, (err.max(), ref.skeleton.names[int(np.argmax(err.max(axis=0)))])
    # with the ground fitting on, the clip changes only where its own feet float or sink (DeepMimic's do)
    fitted = retarget(path, fps=60.0)
    err = np.linalg.norm(fitted.clip.body_pos - ref.body_pos, axis=-1)
    assert err.mean() < 0.02


def test_mink_lifts_bodies_out_of_the_ground(tmp_path):
    """A crawl (hands and knees on the floor) puts the humanoid's pelvis and knees under the ground after the
    two-bone stage; the mink refinement lifts them while the feet and hands stay on their targets."""
    from charctl.motion import import_report as rep
    from charctl.motion.library import load_clip
    from charctl.motion.retarget import retarget
    from charctl.motion.retarget.refine import lowest_points

    path = _turned_copy(load_clip("crawl").resample(60.0), tmp_path / "crawl.bvh")
    plain = retarget(path, refine=False)
    assert lowest_points(plain.clip).min() < -0.03  # the pelvis sphere sinks in
    r = retarget(path)
    q = rep.measure(r)
    assert r.refined_frames > 0 and r.refine_iterations > 0
    assert q.penetration_max_cm <= rep.PENETRATION_TARGET_CM, (q.penetration_max_cm, q.penetration_body)
    assert max(q.ee_error_max_cm.values()) <= rep.EE_TARGET_CM, q.ee_error_max_cm


def test_up_axis_and_units_taken_from_flags(tmp_path):
    from charctl.motion.library import load_clip
    from charctl.motion.retarget import retarget

    clip = load_clip("walk").resample(60.0)
    path = _turned_copy(clip, tmp_path / "copy.bvh")
    detected = retarget(path, ground=False)
    given = retarget(path, up="z", units="cm", ground=False)
    assert not given.source.up_detected and not given.source.units_detected
    assert np.allclose(given.clip.body_pos, detected.clip.body_pos)
    numeric = retarget(path, units="0.01", ground=False)
    assert numeric.source.unit_m == 0.01
    wrong = retarget(path, up="y", ground=False)  # the Z-up file read as Y-up: the character lies down
    assert np.median(wrong.clip.body_pos[:, 2, 1] - wrong.clip.body_pos[:, 0, 1]) < 0.1
    metres = _turned_copy(clip, tmp_path / "m.bvh", scale=1.0, z_up=False)
    r = retarget(metres, ground=False)
    assert (r.source.up, r.source.units) == ("y", "m")


def _renamed(src: Path, dst: Path, names: dict[str, str]) -> Path:
    import re

    text = src.read_text()
    for old, new in names.items():
        text = re.sub(rf"(ROOT|JOINT) {re.escape(old)}\b", rf"\1 {new}", text)
    dst.write_text(text)
    return dst


CMU_TO = {
    "mixamo": {
        **{
            n: "mixamorig:" + n
            for n in [
                "Hips",
                "Spine",
                "Spine1",
                "Neck",
                "Head",
                "LeftUpLeg",
                "LeftLeg",
                "LeftFoot",
                "LeftToeBase",
                "RightUpLeg",
                "RightLeg",
                "RightFoot",
                "RightToeBase",
                "LeftArm",
                "LeftForeArm",
                "LeftHand",
                "RightArm",
                "RightForeArm",
                "RightHand",
            ]
        },  # fmt: skip
        **{"LHipJoint": "mixamorig:LHip", "RHipJoint": "mixamorig:RHip", "LowerBack": "mixamorig:Spine0"},
    },
    "daz": {
        "Hips": "hip",
        "Spine1": "chest",
        "Neck": "neck",
        "Head": "head",
        "LeftUpLeg": "lThigh",
        "LeftLeg": "lShin",
        "LeftFoot": "lFoot",
        "RightUpLeg": "rThigh",
        "RightLeg": "rShin",
        "RightFoot": "rFoot",
        "LeftArm": "lShldr",
        "LeftForeArm": "lForeArm",
        "LeftHand": "lHand",
        "RightArm": "rShldr",
        "RightForeArm": "rForeArm",
        "RightHand": "rHand",
        "LowerBack": "abdomen",
        "LHipJoint": "lHipJ",
        "RHipJoint": "rHipJ",
    },
    "smpl": {
        "Hips": "Pelvis",
        "Spine1": "Spine3",
        "Neck": "Neck",
        "Head": "Head",
        "LeftUpLeg": "L_Hip",
        "LeftLeg": "L_Knee",
        "LeftFoot": "L_Ankle",
        "LeftToeBase": "L_Foot",
        "RightUpLeg": "R_Hip",
        "RightLeg": "R_Knee",
        "RightFoot": "R_Ankle",
        "RightToeBase": "R_Foot",
        "LeftArm": "L_Shoulder",
        "LeftForeArm": "L_Elbow",
        "LeftHand": "L_Wrist",
        "RightArm": "R_Shoulder",
        "RightForeArm": "R_Elbow",
        "RightHand": "R_Wrist",
        "LHipJoint": "L_HipJ",
        "RHipJoint": "R_HipJ",
        "LowerBack": "Spine1",
    },
}


@pytest.mark.parametrize("convention", sorted(CMU_TO))
def test_other_conventions_are_detected_by_their_joint_names(convention, tmp_path):
    from charctl.motion.bvh import read_bvh
    from charctl.motion.skeleton_maps import detect_map

    path = _renamed(DATA / "cmu_walk.bvh", tmp_path / f"{convention}.bvh", CMU_TO[convention])
    assert detect_map(read_bvh(path).names) == convention


def test_user_map_file_gives_the_same_clip_as_the_builtin_map(tmp_path, imported):
    from charctl.motion.retarget import retarget

    r0 = imported["cmu_walk.bvh"]
    names = {n: f"J{i}" for i, n in enumerate(r0.source.names)}
    path = _renamed(DATA / "cmu_walk.bvh", tmp_path / "anon.bvh", names)
    lines = [f"{k}: {names[v]}" for k, v in r0.source.jmap.names.items()] + ["up: y", "units: cmu"]
    (tmp_path / "map.yaml").write_text("\n".join(lines) + "\n")
    with pytest.raises(CharctlError) as e:  # unrecognisable names: detection asks for a map
        retarget(path)
    assert_one_line(e.value, "--skeleton", "MAP.yaml")
    r = retarget(path, skeleton=str(tmp_path / "map.yaml"))
    assert not r.source.up_detected and r.source.units == "cmu"
    assert np.allclose(r.clip.body_pos, r0.clip.body_pos)


# ---------------------------------------------------------------------------- bad input
def _bad_files(tmp: Path) -> dict[str, tuple[Path, list[str], dict]]:
    text = (DATA / "cmu_walk.bvh").read_text()
    head, _, motion = text.partition("MOTION")
    truncated = tmp / "truncated.bvh"
    truncated.write_text(head + "MOTION" + motion[: len(motion) // 2])
    unknown = tmp / "unknown_channel.bvh"
    unknown.write_text(
        text.replace("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 3 Zrotation Yrotation Xscale", 1)
    )
    no_motion = tmp / "no_motion.bvh"
    no_motion.write_text(head)
    not_bvh = tmp / "walk.txt"
    not_bvh.write_text("hello")
    missing_map = tmp / "missing.yaml"
    missing_map.write_text("\n".join(f"{b}: Hips" for b in ["root"]) + "\nchest: Spine1\n")
    wrong_map = tmp / "wrong.yaml"
    body = {
        "root": "Hips",
        "chest": "Spine1",
        "neck": "Head",
        "right_hip": "RightUpLeg",
        "right_knee": "RightLeg",
        "right_ankle": "RightFooot",
        "right_shoulder": "RightArm",
        "right_elbow": "RightForeArm",
        "right_wrist": "RightHand",
        "left_hip": "LeftUpLeg",
        "left_knee": "LeftLeg",
        "left_ankle": "LeftFoot",
        "left_shoulder": "LeftArm",
        "left_elbow": "LeftForeArm",
        "left_wrist": "LeftHand",
    }
    wrong_map.write_text("\n".join(f"{k}: {v}" for k, v in body.items()) + "\n")
    walk = DATA / "cmu_walk.bvh"
    return {
        "truncated-motion": (truncated, ["truncated.bvh", "motion values"], {}),
        "unknown-channel": (unknown, ["unknown_channel.bvh", "Xscale", "LHipJoint"], {}),
        "no-motion-block": (no_motion, ["no_motion.bvh", "malformed BVH"], {}),
        "map-missing-joint": (walk, ["wrong.yaml", "RightFooot", "right_ankle"], {"skeleton": str(wrong_map)}),
        "map-missing-bodies": (walk, ["missing.yaml", "no joint for", "neck"], {"skeleton": str(missing_map)}),
        "builtin-map-mismatch": (walk, ["--skeleton unity", "UpperLeg"], {"skeleton": "unity"}),
        "unknown-skeleton": (walk, ["unknown skeleton", "cmu"], {"skeleton": "vicon"}),
        "bad-up": (walk, ["--up"], {"up": "w"}),
        "bad-units": (walk, ["--units"], {"units": "furlongs"}),
        "start-after-end": (walk, ["--start/--stop", "2 frames"], {"start": 50.0}),
    }


@pytest.mark.parametrize(
    "case",
    [
        "truncated-motion",
        "unknown-channel",
        "no-motion-block",
        "map-missing-joint",
        "map-missing-bodies",
        "builtin-map-mismatch",
        "unknown-skeleton",
        "bad-up",
        "bad-units",
        "start-after-end",
    ],
)
def test_bad_input_is_a_one_line_error(case, tmp_path):
    from charctl.motion.retarget import retarget

    path, words, kwargs = _bad_files(tmp_path)[case]
    with pytest.raises(CharctlError) as e:
        retarget(path, **kwargs)
    assert_one_line(e.value, *words)


CLI_BAD_INPUT = [
    (["{tmp}/truncated.bvh"], ["truncated.bvh", "motion values"]),
    (["{tmp}/unknown_channel.bvh"], ["Xscale"]),
    (["{tmp}/walk.txt"], ["BVH files"]),
    (["{data}/cmu_walk.bvh", "--skeleton", "{tmp}/wrong.yaml"], ["RightFooot"]),
    (["{data}/cmu_walk.bvh", "-o", "{tmp}/out.bvh"], ["ending in .txt"]),
    (["{data}/cmu_walk.bvh", "--fps", "nan"], ["--fps"]),
    (["{data}/cmu_walk.bvh", "-o", "{tmp}"], ["folder"]),
    (["{tmp}/nothing_here.bvh"], ["not found"]),
]


@pytest.mark.parametrize("args,words", CLI_BAD_INPUT)
def test_cli_bad_input_is_one_line_and_writes_nothing(args, words, tmp_path):
    """The first case as a real `charctl` process, the others through charctl.cli.main in this process."""
    _bad_files(tmp_path)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    argv = [a.format(tmp=tmp_path, data=DATA) for a in args]
    run = run_charctl if args == CLI_BAD_INPUT[0][0] else charctl_in_process
    res = run("data", "import", *argv, cwd=tmp_path)
    assert_one_line_error(res, *words)
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # no clip, no report, no imported/ folder


# ---------------------------------------------------------------------------- the command and the clip it writes
@pytest.fixture(scope="module")
def cli_import(tmp_path_factory):
    """`charctl data import` of the Bandai-Namco walk through the real CLI (tracking check included)."""
    work = tmp_path_factory.mktemp("import")
    res = run_charctl(
        "data",
        "import",
        str(DATA / "bandai_namco_walk.bvh"),
        "--name",
        "bn_walk",
        "--label",
        "walk",
        cwd=work,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    return work, work / "imported" / "bn_walk.txt", res.stdout


def test_cli_writes_the_clip_and_its_report(cli_import):
    from charctl.motion import import_report as rep

    work, clip_path, stdout = cli_import
    for suffix in (".txt", ".report.md", ".filmstrip.png", ".quality.json"):
        assert clip_path.with_suffix(suffix).is_file(), suffix
    q = json.loads(clip_path.with_suffix(".quality.json").read_text())
    assert all(q["passes"].values()), q["passes"]
    assert q["tracking_reference_rad"] == rep.DEEPMIMIC_TRACKING_MEDIAN
    assert q["tracking_error_rad"] <= rep.TRACKING_RATIO_TARGET * rep.DEEPMIMIC_TRACKING_MEDIAN
    data = json.loads(clip_path.read_text())
    assert set(data) >= {"Loop", "Frames", "charctl_import"} and len(data["Frames"][0]) == 44
    assert data["charctl_import"]["skeleton"] == "unity" and "skills=[{name: bn_walk" in stdout.replace("\n", "")


def test_imported_clip_loads_wherever_a_clip_name_goes(cli_import):
    from charctl.motion.library import load_clip

    _, clip_path, _ = cli_import
    clip = load_clip(str(clip_path))
    assert (clip.name, clip.label) == ("bn_walk", "walk")
    mirrored = load_clip(f"{clip_path}:mirror")
    assert mirrored.name == "bn_walk:mirror"
    assert np.allclose(mirrored.root_pos[:, 2], -clip.root_pos[:, 2])


def test_imported_clip_feeds_every_experiment(cli_import):
    """cgail skills, the com-cnn clip list and the motion-matching database take the clip file."""
    from charctl.config import compose_config
    from charctl.experiments.cgail.config import Config as CgailConfig
    from charctl.experiments.cgail.skills import load_skills, select_skills
    from charctl.experiments.com_cnn.body import humanoid_body
    from charctl.experiments.com_cnn.config import Config as ComConfig
    from charctl.experiments.com_cnn.sequences import load_deepmimic
    from charctl.experiments.motion_matching.config import Config as MmConfig
    from charctl.experiments.motion_matching.sources import humanoid_sources

    _, clip_path, _ = cli_import
    cfg = compose_config(
        "cgail",
        ["scale=smoke", f"skills=[{{name: mywalk, clip: '{clip_path}', heading_goal: true}}]", "use_skills=[mywalk]"],
        CgailConfig,
    )
    (skill,) = load_skills(select_skills(cfg), cfg.env.control_hz)
    assert skill.clip_name == str(clip_path) and skill.qpos.shape[0] > 60 and skill.mean_speed > 0.5
    com = compose_config("com-cnn", ["scale=smoke", f"data.clips=['{clip_path}']", "data.test_clips=[]"], ComConfig)
    seqs = load_deepmimic(com, humanoid_body(com.com))
    assert seqs and seqs[0].label == "walk"
    mm = compose_config("motion-matching", ["scale=smoke", f"data.clips=['{clip_path}']"], MmConfig)
    sources, info = humanoid_sources(mm)
    assert len(sources) == 2 and info.kind == "humanoid"  # the clip and its mirror


def test_data_show_of_an_imported_clip(cli_import):
    _, clip_path, _ = cli_import
    res = charctl_in_process("data", "show", str(clip_path))
    assert res.returncode == 0, res.stderr
    for word in ("imported_from", "bandai_namco_walk.bvh", "skeleton_map", "unity", "targets_met"):
        assert word in res.stdout


# ---------------------------------------------------------------------------- slow tier
@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REAL))
def test_pd_tracking_of_each_real_file_is_within_target(name, imported, tmp_path):
    from charctl.motion import import_report as rep
    from charctl.motion.imported import write_imported_clip

    path = write_imported_clip(imported[name].clip, tmp_path / "clip.txt", {})
    err, _ = rep.track(path)
    assert err <= rep.TRACKING_RATIO_TARGET * rep.DEEPMIMIC_TRACKING_MEDIAN, err


@pytest.mark.slow
def test_deepmimic_tracking_reference_is_the_measured_median():
    from charctl.motion import import_report as rep

    errs = rep.deepmimic_reference()
    assert len(errs) == 20
    assert abs(np.median(list(errs.values())) - rep.DEEPMIMIC_TRACKING_MEDIAN) < 0.05 * rep.DEEPMIMIC_TRACKING_MEDIAN


@pytest.mark.slow
def test_import_speed_is_at_least_1000_frames_per_second(imported):
    from charctl.motion.retarget import retarget

    frames, seconds = 0, 0.0
    for name in REAL:
        t0 = time.perf_counter()
        r = retarget(DATA / name)
        seconds += time.perf_counter() - t0
        frames += r.source.frames_in_file
    assert frames / seconds >= 1000, frames / seconds


@pytest.mark.slow
def test_end_to_end_import_train_eval_export(tmp_path):
    """The path of docs/motion_import.md on the CMU walk: import it, train an AMP policy on it, evaluate
    survival and fidelity against the imported clip, export the policy. Training from scratch to a policy
    that stays up takes ~2M samples (over 10 min here), so the run here continues the shipped
    `pretrained/amp-walk` (trained on DeepMimic's walk) on the imported clip for ~0.1M samples; it must
    still stay up on the new clip."""
    work = tmp_path
    res = run_charctl("data", "import", str(DATA / "cmu_walk.bvh"), "--name", "cmu_walk", "--no-tracking", cwd=work)
    assert res.returncode == 0, res.stderr
    clip = (work / "imported" / "cmu_walk.txt").resolve()
    run = work / "amp-cmu-walk"
    shutil.copytree(REPO / "pretrained" / "amp-walk", run, ignore=shutil.ignore_patterns("eval*"))
    cfg = (run / "config.yaml").read_text()
    assert "  clip: walk\n" in cfg
    (run / "config.yaml").write_text(cfg.replace("  clip: walk\n", f"  clip: {clip}\n"))  # the skill's clip
    samples = json.loads((run / "metrics.json").read_text()).get("samples", 2_007_040)
    res = run_charctl(
        "train", "cgail", "--resume", str(run), f"train.total_samples={int(samples) + 100_000}", cwd=work, timeout=900
    )
    assert res.returncode == 0, res.stderr
    res = run_charctl("eval", str(run), "--survival", "5", "--fidelity", "-k", "8", "-o", str(work / "ev"), cwd=work,
                      timeout=900)  # fmt: skip
    assert res.returncode == 0, res.stderr
    fid = json.loads((work / "ev" / "fidelity.json").read_text())["skills"]["walk"]
    assert fid["clip"] == str(clip)
    survival = json.loads((work / "ev" / "survival.json").read_text())
    assert "walk" in json.dumps(survival) and fid["no_fall"] >= 0.875, fid["no_fall"]  # stays up on 7 of 8 or more
    res = run_charctl("export", str(run), "--onnx", str(work / "walk.onnx"), cwd=work, timeout=600)
    assert res.returncode == 0, res.stderr
    assert (work / "walk.onnx").stat().st_size > 1000
