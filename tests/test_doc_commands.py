"""Every `charctl ...` command in README.md and docs/*.md works as written.

The commands are extracted from the fenced code blocks and inline code spans of the pages, then:

- fast (every `make test`): each `charctl train` command's config - every job of a `-m` sweep - is
  composed and validated exactly as written (`charctl config EXP job...`), and the cheap commands
  (`data`, `config`, `export bvh`) run as written (both through `charctl.cli.main` in the test process);
- slow (`make test-slow`): every command runs through the real CLI at smoke scale: `scale=smoke`
  appended to train and experiment-level eval/export commands, run placeholders (RUN, RUN_CGAIL,
  outputs/srb/<run>, ...) replaced by smoke runs made for the purpose, optional `[...]` parts dropped,
  `--seconds` and `-k` shrunk. Commands that need the user's own data, a Ray cluster or a display say
  so and are skipped (`play` without a display must still fail with its one-line error).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

from conftest import REPO, assert_one_line_error, charctl_in_process, cli_env, run_charctl

PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
EXPERIMENTS = ("cgail", "srb", "com-cnn", "motion-matching", "hopper-ga")
RUN_PLACEHOLDERS = {"RUN", "RUN_CGAIL", "RUN_AMP", "CGAIL", "AMP", "SRB_RUN", "CGAIL_RUN", "RUN...", "<run>"}


@dataclass(frozen=True)
class DocCommand:
    page: str  # README.md, docs/srb.md
    line: int
    text: str  # as written, comment removed
    inline: bool = False  # from a `code span` in prose rather than a code block

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"

    @property
    def argv(self) -> list[str]:
        return shlex.split(_named_placeholders(self.text))[1:]

    @property
    def page_experiment(self) -> str | None:
        stem = Path(self.page).stem
        return stem if stem in EXPERIMENTS else None


def _strip_comment(line: str) -> str:
    """The command without a trailing `# comment` (a '#' outside quotes preceded by a space)."""
    quote = None
    for i, ch in enumerate(line):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip()
    return line.rstrip()


def doc_commands() -> list[DocCommand]:
    out: list[DocCommand] = []
    for page in PAGES:
        rel = str(page.relative_to(REPO))
        in_block = False
        pending: tuple[int, str] | None = None  # a command continued with a trailing backslash
        for no, raw in enumerate(page.read_text().splitlines(), 1):
            if raw.lstrip().startswith("```"):
                in_block = not in_block
                continue
            if in_block:
                line = raw.strip().removeprefix("$ ")
                if pending is not None:
                    no, line = pending[0], pending[1] + " " + line
                    pending = None
                if line.startswith("charctl ") and line.endswith("\\"):
                    pending = (no, line[:-1].rstrip())
                elif line.startswith("charctl "):
                    out.append(DocCommand(rel, no, _strip_comment(line)))
            else:
                for span in re.findall(r"`(charctl [^`]+)`", raw):
                    out.append(DocCommand(rel, no, span.strip(), inline=True))
    return out


COMMANDS = doc_commands()


def skip_reason(cmd: DocCommand) -> str | None:
    """Why a command cannot run here as written (placeholders for the user's own things), or None."""
    text = cmd.text
    if "..." in text.replace("RUN...", "RUN") and "[" not in text:
        return "an abbreviated form in prose, not a command"
    if "~/" in text or "data.bvh_dir=" in text:
        return "needs the user's own BVH folder"
    if "runtime.address=" in text or re.search(r"--address\s+(?!none\b)\S", text):
        return "joins a running Ray cluster"
    if any(a.startswith("~") for a in cmd.argv):
        return "deletes a key of the small preset; the smoke preset it would run at sets none (test_cgail_presets.py)"
    if len(cmd.argv) < 2 and cmd.argv[:1] != ["play"]:
        return "names a command, not a command line"
    if cmd.inline and all(a.startswith("-") for a in cmd.argv[1:]):
        return "names a command and its flag in prose, not a command line"
    return None


def _named_placeholders(text: str) -> str:
    """`<srb run>` -> SRB_RUN, `<AMP walk run>` / `<cgail AMP walk run>` -> RUN_AMP (no spaces in a token)."""
    text = re.sub(r"<[^>]*srb[^>]*>", "SRB_RUN", text)
    return re.sub(r"<[^>]*(AMP|cgail)[^>]*>", "RUN_AMP", text)


def needs_missing_gpu(cmd: DocCommand) -> bool:
    if "device=cuda" not in cmd.text:
        return False
    import torch

    return not torch.cuda.is_available()


# ---------------------------------------------------------------------------- fast tier
LAUNCHER_FLAGS = ("--launcher", "--address", "--cpus-per-job", "--gpus-per-job")


def _without_launcher_flags(args: list[str]) -> list[str]:
    """The overrides of a train command: the launcher's flags and their values removed."""
    out, skip = [], False
    for a in args:
        if skip:
            skip = False
        elif a in LAUNCHER_FLAGS:
            skip = True
        elif not a.startswith(tuple(f + "=" for f in LAUNCHER_FLAGS)):
            out.append(a)
    return out


def _jobs(argv: list[str]) -> tuple[str, list[list[str]]] | None:
    """(experiment, [overrides of each job]) of a `train` command without --resume, else None."""
    from charctl.config import expand_multirun

    if len(argv) < 2 or argv[0] != "train" or "--resume" in argv:
        return None
    multirun = "-m" in argv or "--multirun" in argv
    overrides = [a for a in _without_launcher_flags(argv[2:]) if a not in ("-m", "--multirun")]
    return argv[1], (expand_multirun(overrides) if multirun else [overrides])


TRAIN_COMMANDS = [c for c in COMMANDS if _jobs(c.argv) and not skip_reason(c)]


def test_the_pages_have_commands():
    assert len(COMMANDS) >= 20 and TRAIN_COMMANDS


@pytest.mark.parametrize("cmd", TRAIN_COMMANDS, ids=[c.id for c in TRAIN_COMMANDS])
def test_train_command_config_is_valid_as_written(cmd, charctl_main):
    if needs_missing_gpu(cmd):
        pytest.skip("a GPU command (device=cuda) on a machine without CUDA")
    experiment, jobs = _jobs(cmd.argv)
    for job in jobs:
        res = charctl_main("config", experiment, *job)
        assert res.returncode == 0, f"{cmd.text!r} (job {' '.join(job)}) in {cmd.id}: {res.stderr.strip()}"


CHEAP = [
    c
    for c in COMMANDS
    if not skip_reason(c) and (c.argv[:1] in (["data"], ["config"]) or c.argv[:2] == ["export", "bvh"])
]


@pytest.mark.parametrize("cmd", CHEAP, ids=[c.id for c in CHEAP])
def test_cheap_command_runs_as_written(cmd, tmp_path):
    res = charctl_in_process(*cmd.argv, cwd=tmp_path)
    assert res.returncode == 0, f"{cmd.text!r} in {cmd.id}: {res.stderr.strip()}"
    assert "Traceback" not in res.stderr


def _value_after(argv: list[str], flag: str) -> str | None:
    """The token after a flag ('' when the flag ends the line or is followed by an option), None without it."""
    if flag not in argv:
        return None
    rest = argv[argv.index(flag) + 1 :]
    return rest[0] if rest and not rest[0].startswith("-") and "=" not in rest[0] else ""


def test_runnable_commands_name_runs_the_slow_tier_can_substitute():
    """What the slow tier would fail on with "not a run directory": a run named by an upper-case word it does not
    substitute (FOLDER, COPY; only the placeholders and an output DIR), a bare `--resume`, and a `--checkpoint`
    other than last.pt (a smoke run keeps no `samples_<n>.pt` of a documented run)."""
    unknown = {
        c.id: tok
        for c in RUNNABLE
        for tok in c.argv
        if re.fullmatch(r"[A-Z][A-Z_]+", tok) and tok not in RUN_PLACEHOLDERS | {"DIR"}
    }
    bare_resume = [c.id for c in RUNNABLE if _value_after(c.argv, "--resume") == ""]
    checkpoints = {c.id: v for c in RUNNABLE if (v := _value_after(c.argv, "--checkpoint")) not in (None, "last.pt")}
    assert (unknown, bare_resume, checkpoints) == ({}, [], {})


# ---------------------------------------------------------------------------- slow tier
# the pages' cgail commands are written for scale=small, whose pose check the smoke preset leaves off: its value,
# read from the small preset, is added to the smoke runs and to the pages' cgail train commands
_SMALL_CGAIL = yaml.safe_load((REPO / "conf/preset/cgail/small.yaml").read_text())
SMALL_POSE_CHECK = f"reward.pose_error_threshold={_SMALL_CGAIL['reward']['pose_error_threshold']}"
SMOKE_RUNS = {
    # the skills the pages' cgail commands name (walk, run, right_kick); AMP = the unconditional baseline
    "cgail": ["train", "cgail", "scale=smoke", "use_skills=[walk,run,right_kick]", SMALL_POSE_CHECK],
    # a mirrored pair for the pages' `--resume RUN ppo.mirror_loss=...` (the loss needs a skill and its mirror)
    "cgail-mirror": [
        "train",
        "cgail",
        "scale=smoke",
        "use_skills=[walk,right_kick,left_kick]",
        SMALL_POSE_CHECK,
    ],
    "cgail-amp": ["train", "cgail", "scale=smoke", "use_skills=[walk]", "cgail.conditional=false"],
    "srb": ["train", "srb", "scale=smoke"],
    "com-cnn": ["train", "com-cnn", "scale=smoke"],
    "motion-matching": ["train", "motion-matching", "scale=smoke"],
    "hopper-ga": ["train", "hopper-ga", "scale=smoke"],
}


@pytest.fixture(scope="module")
def smoke_runs(tmp_path_factory):
    """Lazily made smoke runs under <work>/outputs (so `charctl eval srb` finds the latest one)."""
    work = tmp_path_factory.mktemp("doc-commands")
    made: dict[str, Path] = {}

    def get(kind: str) -> Path:
        if kind not in made:
            exp = SMOKE_RUNS[kind][1]
            before = set((work / "outputs" / exp).glob("*"))
            res = run_charctl(*SMOKE_RUNS[kind], f"output_root={work / 'outputs'}", cwd=work, timeout=600)
            assert res.returncode == 0, res.stderr
            (made[kind],) = set((work / "outputs" / exp).glob("*")) - before
        return made[kind]

    def copy(run: Path) -> Path:
        """A fresh copy of a run (resuming it must not change the run other commands use)."""
        n = len(list(run.parent.glob(run.name + "_copy*")))
        dest = run.parent / f"{run.name}_copy{n}"
        shutil.copytree(run, dest)
        return dest

    get.work = work
    get.copy = copy
    return get


def _run_kind(token: str, cmd: DocCommand, position: int) -> str:
    """Which smoke run a placeholder stands for."""
    m = re.match(r"outputs/([a-z-]+)/", token)
    if m:
        return m.group(1)
    if token in ("RUN_AMP", "AMP", "CGAIL_RUN"):
        return "cgail-amp"
    if token in ("RUN_CGAIL", "CGAIL"):
        return "cgail"
    if "ppo.mirror_loss=" in cmd.text:
        return "cgail-mirror"
    if token == "SRB_RUN":
        return "srb"
    exp = cmd.page_experiment or "cgail"
    return "cgail-amp" if exp == "cgail" and position > 0 else exp


RUNNABLE = [c for c in COMMANDS if not skip_reason(c)]
# resuming a finished smoke run needs a larger budget, named by each experiment's own key (runner budget_key)
RESUME_BUDGET = {
    "cgail": "train.total_samples=1024",
    "srb": "train.total_samples=4096",
    "hopper-ga": "ga.generations=4",  # conf/preset/hopper-ga/smoke.yaml: 3
    "com-cnn": "train.steps=90",  # conf/preset/com-cnn/smoke.yaml: 60
}


def _pretrained_resume_copy(folder: Path, cwd: Path) -> list[str]:
    """A resume of a committed run: a copy of its folder in the test's directory and a budget one
    iteration past its samples (the committed config.yaml and checkpoints stay as they are)."""
    copy = cwd / folder.name
    shutil.copytree(folder, copy)
    done = json.loads((folder / "metrics.json").read_text())["samples"]
    return [str(copy), f"train.total_samples={done + 1}"]


def smoke_argv(cmd: DocCommand, runs, cwd: Path) -> list[str]:
    """The command at smoke scale: placeholders -> smoke runs (a fresh copy for --resume), optional
    `[...]` parts dropped, `--seconds` / `-k` shrunk to 1, `--after` to 0 (a smoke run keeps its checkpoints from
    its first samples), scale=smoke and output_root appended."""
    text = re.sub(r"(?<=\s)\[[^\]]*\]", "", _named_placeholders(cmd.text))  # optional "[-k 4]", "[RUN ...]"
    argv = shlex.split(text)[1:]
    resume = "--resume" in argv
    out: list[str] = []
    seen_runs = 0
    skip_next = False
    for tok in argv:
        if skip_next:
            skip_next = False
            continue
        is_run = tok in RUN_PLACEHOLDERS or (tok.startswith("outputs/") and tok.count("/") >= 2)
        key, _, value = tok.partition("=")
        if value in RUN_PLACEHOLDERS:  # push.baseline_run=RUN_AMP
            out.append(f"{key}={runs(_run_kind(value, cmd, 1))}")
        elif is_run:
            run = runs(_run_kind(tok, cmd, seen_runs))
            out.append(str(runs.copy(run) if resume else run))
            seen_runs += 1
        elif tok in ("--seconds", "-k", "--episodes"):
            out += [tok, "1"]
            skip_next = True
        elif tok == "--after":
            out += [tok, "0"]
            skip_next = True
        elif tok.startswith("train.total_samples="):
            out.append("train.total_samples=8192")
        elif tok.startswith("pretrained/") and resume:  # never train into a committed folder: a copy, one step on
            out += _pretrained_resume_copy(REPO / tok, cwd)
        elif tok.startswith("pretrained/"):  # a shipped policy: the repository's folder (the command runs elsewhere)
            out.append(str(REPO / tok))
        else:
            out.append(tok)
    if "my_path.csv" in text:  # the user's path file, in the format the command reads
        body = "t,x,y,z\n0,0,0.9,0\n1,1,0.9,0\n2,2,0.9,0.5\n" if "--com-path" in text else "x,z\n0,0\n2,0\n2,2\n0,2\n"
        (cwd / "my_path.csv").write_text(body)
    command = out[0] if out else ""
    target = out[1] if len(out) > 1 else ""
    if command == "train" and resume:
        budget = RESUME_BUDGET.get(target, "")
        if budget and not any(a.startswith(budget.partition("=")[0] + "=") for a in out):
            out.append(budget)
    elif command in ("train", "tune"):
        out += ["scale=smoke", f"output_root={runs.work / 'outputs'}"]
        if target == "cgail" and not any(a.startswith("reward.pose_error_threshold=") for a in out):
            out.append(SMALL_POSE_CHECK)
    elif command in ("eval", "export") and target == "motion-matching":
        out += ["scale=smoke", f"output_root={runs.work / 'outputs'}"]
    elif command in ("eval", "export", "play") and target in EXPERIMENTS:
        runs(target)  # the latest run of the experiment under <work>/outputs must exist
    if command == "eval" and "-k" not in out and any(k in " ".join(out) for k in ("/cgail", "/srb", " srb", " cgail")):
        out += ["-k", "1"]
    if (
        command == "eval"
        and any(t.startswith(str(REPO / "pretrained")) for t in out)
        and not {"-o", "--out"} & set(out)
    ):
        out += ["-o", str(cwd / "eval-out")]  # never write into a committed folder's eval/
    return out


@pytest.mark.slow
@pytest.mark.parametrize("cmd", RUNNABLE, ids=[c.id for c in RUNNABLE])
def test_doc_command_runs_at_smoke_scale(cmd, smoke_runs):
    if needs_missing_gpu(cmd):
        pytest.skip("a GPU command (device=cuda) on a machine without CUDA")
    work = smoke_runs.work
    argv = smoke_argv(cmd, smoke_runs, work)
    if argv[0] == "play" and not os.environ.get("DISPLAY"):
        if len(argv) == 1:
            argv.append(str(smoke_runs("cgail")))
        res = run_charctl(*argv, cwd=work)
        assert res.returncode == 2, res.stderr
        assert_one_line_error(res, "export", "--video")  # documented: needs a display, points to the video
        return
    res = run_charctl(*argv, cwd=work, env=cli_env(), timeout=900)
    assert res.returncode == 0, f"{cmd.text!r} ({cmd.id}) as {' '.join(argv)}:\n{res.stderr[-2000:]}"
    assert "Traceback" not in res.stderr


def test_smoke_argv_substitutions(tmp_path):
    """The rewriting itself (no run is made: placeholders resolve to fake paths)."""

    def runs(kind: str) -> Path:
        return Path(f"/runs/{kind}")

    runs.work = tmp_path
    runs.copy = lambda run: Path(f"{run}_copy")
    cmd = DocCommand("docs/cgail.md", 1, "charctl eval RUN_CGAIL RUN_AMP --dtw [-k 4] [-o DIR] --switch walk run")
    assert smoke_argv(cmd, runs, tmp_path) == [
        "eval",
        "/runs/cgail",
        "/runs/cgail-amp",
        "--dtw",
        "--switch",
        "walk",
        "run",
        "-k",
        "1",
    ]
    cmd = DocCommand("docs/srb.md", 1, "charctl train srb --resume outputs/srb/<run> train.total_samples=3000000")
    assert smoke_argv(cmd, runs, tmp_path) == ["train", "srb", "--resume", "/runs/srb_copy", "train.total_samples=8192"]
    committed = REPO / "pretrained/cgail-3skill-fidelity"  # a committed run is resumed from a copy, one iteration on
    samples = json.loads((committed / "metrics.json").read_text())["samples"]
    cmd = DocCommand("x.md", 1, "charctl train cgail --resume pretrained/cgail-3skill-fidelity")
    argv = smoke_argv(cmd, runs, tmp_path)
    assert argv == [
        "train",
        "cgail",
        "--resume",
        str(tmp_path / committed.name),
        f"train.total_samples={samples + 1}",
    ]
    assert (tmp_path / committed.name / "config.yaml").read_text() == (committed / "config.yaml").read_text()
    cmd = DocCommand("x.md", 1, "charctl eval pretrained/tracking-3skill --fidelity -k 4")  # a committed folder
    argv = smoke_argv(cmd, runs, tmp_path)
    assert argv == [
        "eval",
        str(REPO / "pretrained/tracking-3skill"),
        "--fidelity",
        "-k",
        "1",
        "-o",
        str(tmp_path / "eval-out"),
    ]
    cmd = DocCommand("README.md", 1, "charctl train com-cnn -m data.history=45,90 model.kernel=2,5")
    assert smoke_argv(cmd, runs, tmp_path)[-2:] == ["scale=smoke", f"output_root={tmp_path / 'outputs'}"]
    line = 'charctl export RUN --commands "a:0,b:3"   # a # comment'
    assert _strip_comment(line) == 'charctl export RUN --commands "a:0,b:3"'
