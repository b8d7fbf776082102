"""Every `charctl eval` and `charctl export` mode, and `charctl train`, checks its arguments before it writes.

One case per mode (each experiment's eval modes, its export outputs, and the clip exports): a bad
argument of that mode gives exit 2, exactly one `error:` line naming it, no traceback, and nothing on
disk: the output folder the command was pointed at stays absent, and nothing appears in the sandbox
(output_root, a new run directory) or in the run directories it read. Several cases are the ones that
used to fail only after a first file was written: an unknown sweep case (config.yaml in -o), a second
hopper-ga run without a checkpoint (the first run's figures), the web demo of a tracking run (the ONNX
file), --fps on a BVH-folder skeleton (a new run directory), a missing --checkpoint with --curves, a sweep's
missing data.bvh_dir, unknown clip or too low data.fps (config.yaml in -o, or a new run directory), a
sweep case whose database has too few searchable frames, and a runtime.exclude_window that leaves a search
nothing to choose from (config.yaml in -o or a new run directory, after the cases before it ran; export: a
traceback).

`charctl train` likewise (`TRAIN`): a config whose data cannot be trained (the experiment's `preflight`: an unknown
clip, a motion-matching database with too few searchable frames, a reference clip srb cannot follow) is a one-line
error before the run directory is made, before the first one of a `-m` sweep whose later job is the bad one, and
before a `--resume` writes to the run; it used to come after (a run directory with config.yaml, or a rewritten
config.yaml and resumes.txt).

On a machine that cannot render, the modes that render (`NO_RENDER`) give their one-line error before
anything is written: it used to come after com-cnn's CSV, plot and BVH, hopper-ga's BVH and
motion-matching's run directory and BVH.

The commands run in this process (`charctl_main`: the console script's error handling without an
interpreter start per case); shipped policies from pretrained/ are read, never written.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from conftest import REPO, assert_one_line_error, snapshot

PRETRAINED = REPO / "pretrained"

# (id, arguments, words the error line must contain). Placeholders: {out} the folder the command writes to
# (must stay absent), {tmp} the sandbox, {cgail} / {amp} / {tracking} shipped cgail / AMP / tracking policies,
# {srb} / {com} / {hopper} smoke runs, {hopper_bare} a copy of the hopper-ga run without its checkpoint,
# {mocap} a folder with one BVH file.
MODES = [
    # eval: cgail
    ("eval-cgail-dtw", "eval {cgail} --dtw -k 1 --checkpoint nosuch.pt -o {out}", ["nosuch.pt"]),
    ("eval-cgail-confusion", "eval {amp} --confusion -k 1 -o {out}", ["--confusion", "conditional"]),
    ("eval-cgail-switch", "eval {cgail} --switch walk nosuch -k 1 -o {out}", ["nosuch"]),
    ("eval-cgail-switch-matrix", "eval {amp} --switch-matrix -k 1 -o {out}", ["--switch-matrix", "conditional"]),
    ("eval-cgail-curves", "eval {cgail} --curves --checkpoint nosuch.pt -o {out}", ["nosuch.pt"]),
    ("eval-cgail-survival", "eval {cgail} --survival 1 --switch walk nosuch -k 1 -o {out}", ["nosuch"]),
    ("eval-cgail-fidelity", "eval {cgail} --fidelity -k 1 -o {out} device=tpu", ["tpu"]),
    ("eval-cgail-checkpoints", "eval {cgail} --checkpoints --rank nosuch -o {out}", ["--rank", "nosuch"]),
    ("eval-cgail-min-no-fall", "eval {cgail} --checkpoints --min-no-fall 1.5 -o {out}", ["--min-no-fall", "<= 1"]),
    ("eval-cgail-min-diagonal", "eval {cgail} --checkpoints --min-diagonal 2 -o {out}", ["--min-diagonal", "<= 1"]),
    # eval: the other experiments
    ("eval-srb-push", "eval {srb} --push -k 1 -o {out} push.baseline_run={tmp}/nosuch", ["nosuch"]),
    ("eval-com-cnn-pose-error", "eval {com} --pose-error -o {out} data.test_clips=[]", ["held-out"]),
    ("eval-com-cnn-dtw", "eval {com} --dtw -o {out} nosuch.key=1", ["nosuch"]),
    ("eval-com-cnn-checkpoints", "eval {com} --checkpoints --after 1e12 -o {out}", ["no checkpoint", "1,000,000,000"]),
    (
        "eval-mm-sweep",
        "eval motion-matching --sweep scale=smoke sweep.cases=[99] output_root={tmp}/runs -o {out}",
        ["sweep.cases", "99"],
    ),
    (
        "eval-mm-sweep-bvh-dir",
        "eval motion-matching --sweep scale=smoke output_root={tmp}/runs data.bvh_dir={tmp}/nosuch -o {out}",
        ["data.bvh_dir", "nosuch"],
    ),
    (  # no -o: the sweep's new run directory under output_root must not be made either
        "eval-mm-sweep-clips",
        "eval motion-matching --sweep scale=smoke output_root={tmp}/runs data.clips=[nosuch_clip]",
        ["nosuch_clip"],
    ),
    (  # case 1 has 11 searchable frames, case 10 (2 past samples) 1: the sweep used to run case 1 first
        "eval-mm-sweep-searchable",
        "eval motion-matching --sweep scale=smoke output_root={tmp}/runs sweep.cases=[1,10] data.clips=[kick] "
        "data.mirror=false runtime.end_buffer=140 -o {out}",
        ["1 searchable frames"],
    ),
    (  # the one clip (kick, not mirrored) is inside the exclusion window of every frame: the first search failed
        "eval-mm-sweep-exclude",
        "eval motion-matching --sweep scale=smoke output_root={tmp}/runs data.clips=[kick] data.mirror=false "
        "runtime.exclude_window=1000",
        ["runtime.exclude_window", "clip 'kick'"],
    ),
    (  # a 10-frame window leaves case 1 (kick frames 0..40 searchable) frames to jump to from every frame, not
        # case 10 (frames 10..21) from its frames 12..19: the sweep used to run case 1 first
        "eval-mm-sweep-exclude-case",
        "eval motion-matching --sweep scale=smoke output_root={tmp}/runs sweep.cases=[1,10] data.clips=[kick] "
        "data.mirror=false runtime.exclude_window=40 -o {out}",
        ["runtime.exclude_window", "frame 12 of clip 'kick': all 12"],
    ),
    (
        "eval-mm-sweep-fps",
        "eval motion-matching --sweep scale=smoke output_root={tmp}/runs data.fps=1 -o {out}",
        ["data.fps"],
    ),
    ("eval-hopper-curves", "eval {hopper} {hopper_bare} --curves -o {out}", ["no checkpoint"]),
    ("eval-hopper-checkpoints", "eval {hopper_bare} --checkpoints -o {out}", ["no checkpoint to evaluate"]),
    # export: clips
    ("export-clip-bvh", "export bvh nosuch_clip -o {out}/w.bvh", ["nosuch_clip"]),
    ("export-clip-video", "export video walk --fps 0 -o {out}/w.mp4", ["--fps"]),
    # export: cgail
    ("export-cgail-onnx", "export {cgail} --onnx {out}/p.onnx --commands walk:0,nosuch:1", ["nosuch"]),
    ("export-cgail-torchscript", "export {cgail} --torchscript {out}/p.pt --checkpoint nosuch.pt", ["nosuch.pt"]),
    ("export-cgail-bvh", "export {cgail} --bvh {out}/r.bvh --commands walk:-1", ["-1", "--commands"]),
    ("export-cgail-video", "export {cgail} --video {out}/r.mp4 --seconds 0", ["--seconds"]),
    ("export-cgail-web", "export {tracking} --onnx {out}/p.onnx --web {out}/site", ["tracking run"]),
    # export: the other experiments
    ("export-srb-video", "export {srb} --video {out}/v.mp4 --seconds -2", ["--seconds"]),
    ("export-com-cnn-bvh", "export {com} --bvh {out}/g.bvh --com-path nosuch", ["nosuch"]),
    ("export-com-cnn-video", "export {com} --video {out}/g.mp4 --crouch-at -1", ["--crouch-at"]),
    (
        "export-mm-bvh",
        "export motion-matching scale=smoke output_root={tmp}/runs data.bvh_dir={mocap} --bvh {out}/x.bvh --fps 30",
        ["--fps", "data.bvh_dir"],
    ),
    (
        "export-mm-video",
        "export motion-matching scale=smoke output_root={tmp}/runs path=nosuch --video {out}/x.mp4",
        ["nosuch"],
    ),
    (  # the rollout's first search used to fail
        "export-mm-bvh-exclude",
        "export motion-matching scale=smoke output_root={tmp}/runs data.clips=[kick] data.mirror=false "
        "runtime.exclude_window=1000 --bvh {out}/x.bvh",
        ["runtime.exclude_window", "clip 'kick'"],
    ),
    ("export-hopper-bvh", "export {hopper} --bvh {out}/h.bvh --seconds 0", ["--seconds"]),
    ("export-hopper-video", "export {hopper} --video {out}/h.mp4 --fps -5", ["--fps"]),
]

# `charctl train` (id, arguments, words): a config its data cannot train (the experiment's `preflight`) is refused
# before the run directory is made (all of a sweep's jobs before the first), or a resumed run is written to
TRAIN = [
    (  # kick (not a loop) has no frame left once the last 1000 (120 Hz) frames are never searched
        "train-mm-searchable",
        "train motion-matching scale=smoke output_root={tmp}/runs data.clips=[kick] data.mirror=false "
        "runtime.end_buffer=1000",
        ["0 searchable frames"],
    ),
    (  # the first job (end_buffer 20) is fine: its run directory used to be made, and trained, first
        "train-mm-multirun",
        "train motion-matching scale=smoke output_root={tmp}/runs data.clips=[kick] data.mirror=false "
        "runtime.end_buffer=20,1000 -m",
        ["0 searchable frames"],
    ),
    ("train-mm-case", "train motion-matching scale=smoke output_root={tmp}/runs case=best", ["case=best", "sweep"]),
    (
        "train-cgail-clip",
        "train cgail scale=smoke output_root={tmp}/runs skills=[{{name:walk,clip:nosuch_clip}}] use_skills=[walk]",
        ["nosuch_clip"],
    ),
    ("train-srb-clip", "train srb scale=smoke output_root={tmp}/runs reference.clip=kick", ["kick", "walking clip"]),
    (
        "train-srb-inertia-frame",
        "train srb scale=smoke output_root={tmp}/runs body.inertia_pose_frame=100000",
        ["inertia_pose_frame=100000", "frames 0.."],
    ),
    (  # the checkpoint used to load first: config.yaml rewritten with the clip and resumes.txt made, then the error
        "train-srb-resume",
        "train srb --resume {srb} reference.clip=kick train.total_samples=4096",
        ["kick", "walking clip"],
    ),
    (
        "train-com-cnn-clip",
        "train com-cnn scale=smoke output_root={tmp}/runs data.clips=[nosuch_clip] data.test_clips=[]",
        ["nosuch_clip"],
    ),
    ("train-com-cnn-bvh", "train com-cnn scale=smoke output_root={tmp}/runs data.bvh_dir={mocap}", ["com.bvh_joints"]),
]

# (id, arguments) of the modes that render, run on a machine that cannot: the one-line error before any file
NO_RENDER = [
    ("eval-cgail-fidelity", "eval {cgail} --fidelity -k 1 -o {out}"),
    ("export-clip-video", "export video walk -o {out}/w.mp4"),
    ("export-cgail-video", "export {cgail} --onnx {out}/p.onnx --bvh {out}/r.bvh --video {out}/r.mp4"),
    ("export-srb-video", "export {srb} --video {out}/v.mp4 --seconds 1"),
    ("export-com-cnn-video", "export {com} --bvh {out}/g.bvh --video {out}/g.mp4"),
    (
        "export-mm-video",
        "export motion-matching scale=smoke output_root={tmp}/runs --bvh {out}/x.bvh --video {out}/x.mp4",
    ),
    ("export-hopper-video", "export {hopper} --bvh {out}/h.bvh --video {out}/h.mp4"),
]


@pytest.fixture(scope="module")
def runs(smoke_run, tmp_path_factory) -> dict[str, Path]:
    """The run directories the cases read (smoke runs of srb, com-cnn and hopper-ga; shipped cgail policies)."""
    root = tmp_path_factory.mktemp("mode-args")
    hopper = smoke_run("hopper-ga")
    bare = Path(shutil.copytree(hopper, root / "hopper-ga" / "bare"))
    (bare / "checkpoints" / "last.pt").unlink()
    mocap = root / "mocap"
    from charctl.motion.bvh import write_bvh
    from charctl.motion.library import load_clip

    write_bvh(load_clip("walk"), mocap / "walk.bvh")
    return {
        "cgail": PRETRAINED / "cgail-3skill-fidelity",
        "amp": PRETRAINED / "amp-walk",
        "tracking": PRETRAINED / "tracking-walk",
        "srb": smoke_run("srb"),
        "com": smoke_run("com-cnn"),
        "hopper": hopper,
        "hopper_bare": bare,
        "mocap": mocap,
    }


def test_every_mode_has_a_case():
    """Each eval mode option and each export output of every experiment has its case above."""
    from charctl.experiments import EXPERIMENTS, load

    short = {"cgail": "cgail", "srb": "srb", "com-cnn": "com-cnn", "motion-matching": "mm", "hopper-ga": "hopper"}
    ids = {case[0] for case in MODES}
    outputs = ("onnx", "torchscript", "bvh", "video", "web")
    for name in EXPERIMENTS:
        exp = load(name)
        for o in exp.eval_options:
            if o.mode:
                assert f"eval-{short[name]}-{o.flag[2:]}" in ids, (name, o.flag)
        for o in exp.export_options:
            if o.name in outputs:
                assert f"export-{short[name]}-{o.flag[2:]}" in ids, (name, o.flag)
    assert {"export-clip-bvh", "export-clip-video"} <= ids


@pytest.mark.parametrize("case", MODES, ids=[c[0] for c in MODES])
def test_a_bad_argument_writes_nothing(case, runs, tmp_path, charctl_main, monkeypatch):
    name, template, words = case
    if name == "export-cgail-web":  # the web demo's npm packages need not be installed for its arguments' check
        import charctl.experiments.cgail.web_site as web_site

        monkeypatch.setattr(web_site, "check_web_sources", lambda *a, **k: None)
    assert_writes_nothing(charctl_main, template, words, runs, tmp_path)


@pytest.mark.parametrize("case", TRAIN, ids=[c[0] for c in TRAIN])
def test_a_config_its_data_cannot_train_writes_nothing(case, runs, tmp_path, charctl_main):
    assert_writes_nothing(charctl_main, case[1], case[2], runs, tmp_path)


@pytest.mark.parametrize("case", NO_RENDER, ids=[c[0] for c in NO_RENDER])
def test_a_machine_that_cannot_render_writes_nothing(case, runs, tmp_path, charctl_main, monkeypatch):
    """No OpenGL (charctl.viz.video.make_renderer fails): the error comes before any other output is written."""
    import charctl.viz.video as video
    from charctl.errors import CharctlError

    def no_gl(*args, **kwargs):
        raise CharctlError("cannot render with MUJOCO_GL=osmesa (no libOSMesa); install Debian's libosmesa6")

    monkeypatch.setattr(video, "make_renderer", no_gl)
    assert_writes_nothing(charctl_main, case[1], ["cannot render"], runs, tmp_path)


def test_share_options_are_bounded_by_one():
    """--min-no-fall and --min-diagonal are shares: 0 and 1 pass, above 1 is a one-line error naming the flag."""
    from charctl.errors import CharctlError
    from charctl.options import check_options

    for name in ("min_no_fall", "min_diagonal"):
        check_options({name: 0.0})
        check_options({name: 1.0})
        with pytest.raises(CharctlError, match=f"--{name.replace('_', '-')} must be <= 1, got 1.01"):
            check_options({name: 1.01})


def assert_writes_nothing(charctl_main, template: str, words: list[str], runs: dict[str, Path], tmp_path: Path) -> None:
    """The command `template` exits 2 with one `error:` line containing `words`; {out} stays absent and
    nothing appears in the sandbox or in the run directories the command names."""
    out = tmp_path / "out"
    values = {"out": out, "tmp": tmp_path, **runs}
    watched = [tmp_path] + [p for key, p in runs.items() if "{" + key + "}" in template]
    before = snapshot(*watched)
    res = charctl_main(*[a.format(**values) for a in template.split()])
    assert res.returncode == 2, f"exit {res.returncode}:\n{res.stdout}\n{res.stderr}"
    assert_one_line_error(res, *[w.format(**values) for w in words])
    assert not out.exists(), f"{out} was made: {sorted(snapshot(out))}"
    assert sorted(snapshot(*watched) - before) == []
