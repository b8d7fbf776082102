"""`charctl eval RUN --checkpoints` for cgail: every kept checkpoint (train.keep_checkpoint_every) against
the ten-skill targets, and the rule that picks one (the loop, the choice and its confirmation on fresh
starts: charctl/commands/eval_checkpoints.py).

    charctl eval RUN --checkpoints [--survival 5] [-k 64] [--confusion-k 16] [--min-no-fall 0.8]
        [--min-diagonal 0.9] [--seed 4321] [--confirm-seed 7] [--after N] [--fidelity] [--fidelity-k 4]
        [--rank fidelity|margin] [--min-coverage 0.5] [-o DIR] [device=cpu|cuda]

For each checkpoints/samples_<n>.pt (and last.pt) it runs what `charctl eval RUN --checkpoint F
--survival SECONDS -k K` and `--confusion -k CK` run, into OUT/<checkpoint>/ (OUT: -o, default RUN/eval/),
then writes

- OUT/checkpoints.json and checkpoints.md: per checkpoint, every skill's no-fall share and
  Fig 6.8 diagonal (mean classifier probability of the commanded skill on the policy's motion),
  the worst of each, and whether both targets hold;
- OUT/checkpoints.png: worst no-fall and lowest diagonal against samples, with the targets.

With fidelity (`--fidelity`, or the default `--rank fidelity`) each checkpoint also gets what
`charctl eval RUN --checkpoint F --fidelity -k FK` measures (docs/cgail.md, "Fidelity": pose coverage,
DTW body-position error and the signature per skill, without the filmstrips; the chosen checkpoint's
re-evaluation draws them): the table gains the lowest coverage over the skills and a coverage per
skill, the plot a line.

Selection: `--rank fidelity` (the default; implies `--fidelity`): the most skills performed, that is at pose
coverage >= `--min-coverage` (default 0.5, the ten-skill target) with their named signatures within 30 % of the
clip's (the kicks' and the spinkick's foot peak, the jump's airborne share, the spins' yaw rate;
charctl/experiments/cgail/signatures.py: a guard covers 0.45 of the kick clip without lifting the foot), ties
broken by the largest lowest-coverage over the skills, then the worst no-fall, then the lowest diagonal (why the
count first: docs/cgail.md, "Fidelity"). `--rank margin`: the checkpoint that meets both targets with the largest
margin (the smaller of worst no-fall - min_no_fall and min diagonal - min_diagonal), else the one closest to
meeting them. Each checkpoint's result is kept in
OUT/<checkpoint>/row.json and reused while its settings match. Policies run on the CPU unless a
`device=` override says otherwise.

An AMP (unconditional) run has no classifier, so no diagonal: its checkpoints are ranked by fidelity
(the rollouts force each skill's clip at the reset, which an AMP policy follows without a command), ties
broken by the worst no-fall; `--rank margin`, `--confusion-k` and `--min-diagonal` are refused for it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from charctl.errors import CharctlError
from charctl.experiments.cgail.checkpoints_report import skills_performed, write_report

RANKS = ("fidelity", "margin")  # --rank; the first is the default (the fidelity metric, where cgail has it)
SECONDS = 5.0  # no-fall episode length without --survival
EPISODES = 64  # no-fall episodes per skill without -k
CONFUSION_EPISODES = 16
FIDELITY_EPISODES = 4
MIN_NO_FALL = 0.8
MIN_DIAGONAL = 0.9
MIN_COVERAGE = 0.5  # --rank fidelity counts the skills at pose coverage >= this with their named signatures met
# (issue 24's ten-skill target; charctl/experiments/cgail/signatures.py)
SEED = 4321
CONFIRM_SEED = 7
OTHER_MODES = ("dtw", "confusion", "switch", "curves")  # modes --checkpoints does not combine with
CLASSIFIER_OPTIONS = ("confusion_k", "min_diagonal")  # options of the Fig 6.8 diagonal (refused for an AMP run)


def margin(worst_no_fall: float, min_diagonal: float, min_no_fall: float, min_diag: float) -> float:
    """How far a checkpoint clears both targets (negative: how far it misses the worse one)."""
    return min(worst_no_fall - min_no_fall, min_diagonal - min_diag)


def rank_key(row: dict, rank: str, min_coverage: float = MIN_COVERAGE) -> tuple:
    """Sort key of a checkpoint's row (larger is better) under selection rule `rank` (see the module doc)."""
    if rank == "fidelity":
        key = (skills_performed(row, min_coverage), row["min_coverage"], row["worst_no_fall"])
        return key if row["min_diagonal"] is None else (*key, row["min_diagonal"])  # None: an AMP run
    return (row["margin"],)


def cached_row(out: Path, name: str, samples: int, seconds: float, k: int, ck: int, seed: int) -> dict | None:
    """The row written by an earlier evaluation with the same settings (re-runs evaluate only new
    checkpoints), or None."""
    path = out / "row.json"
    if not path.is_file():
        return None
    row = json.loads(path.read_text())
    same = row.get("settings") == {"seconds": seconds, "k": k, "confusion_k": ck, "seed": seed}
    # a row written before the argmax accuracy was recorded is evaluated again
    current = same and "class_acc" in row
    return row if current and row.get("checkpoint") == name and row.get("samples") == samples else None


def evaluate_checkpoint(
    run_dir: Path,
    name: str,
    samples: int,
    seconds: float,
    k: int,
    ck: int,
    seed: int,
    out: Path,
    fidelity_k: int = 0,
    filmstrips: bool = False,
    device: str = "cpu",
) -> dict:
    """No-fall and Fig 6.8 diagonal per skill of one checkpoint, and with `fidelity_k` > 0 its fidelity
    over that many episodes per skill (each part reused from out/row.json when its settings match)."""
    from charctl.experiments.cgail.rollouts import load_eval_run
    from charctl.files import atomic_write_text, strict_json

    row = cached_row(out, name, samples, seconds, k, ck, seed)
    tr = None
    if row is None:
        tr = load_eval_run(run_dir, device, name)  # loaded before its folder is made
        out.mkdir(parents=True, exist_ok=True)
        row = survival_and_confusion(tr, name, seconds, k, ck, seed, out)
        atomic_write_text(out / "row.json", strict_json(row))
    wanted = {"k": fidelity_k, "seed": seed}
    have = row.get("fidelity") or {}
    # a row written before the named signatures were recorded is evaluated again
    if fidelity_k > 0 and (have.get("settings") != wanted or "signature_met" not in have):
        from charctl.experiments.cgail.fidelity import eval_fidelity
        from charctl.experiments.cgail.signatures import signatures_met

        tr = tr or load_eval_run(run_dir, device, name)
        res = eval_fidelity([tr], fidelity_k, out, seed=seed, filmstrips=filmstrips)["skills"]
        peak = {s: max(r["policy"]["right_foot_peak"], r["policy"]["left_foot_peak"]) for s, r in res.items()}
        clip_peak = {
            s: max(r["reference"]["right_foot_peak"], r["reference"]["left_foot_peak"]) for s, r in res.items()
        }
        row["fidelity"] = {
            "settings": wanted,
            "coverage": {s: r["coverage"] for s, r in res.items()},
            "body_error": {s: r["body_error"] for s, r in res.items()},
            "foot_peak": peak,
            "foot_peak_clip": clip_peak,
            "airborne": {s: r["policy"]["airborne"] for s, r in res.items()},
            "signature_met": {s: signatures_met(r) for s, r in res.items()},  # the target's named signatures
            "no_fall": {s: r["no_fall"] for s, r in res.items()},  # of the fidelity episodes (RSI at frame 0)
        }
        row["min_coverage"] = min(row["fidelity"]["coverage"].values())
        atomic_write_text(out / "row.json", strict_json(row))
    return row


def survival_and_confusion(tr, name: str, seconds: float, k: int, ck: int, seed: int, out: Path) -> dict:
    """The no-fall / diagonal row of one loaded checkpoint (an AMP run's diagonal and class accuracy: None)."""
    from charctl.experiments.cgail.evaluate import eval_confusion, eval_survival

    surv = eval_survival([tr], k, seconds, out, seed=seed)
    no_fall = {s: row[f"{tr.label} no-fall"] for s, row in surv["table"].items()}
    diagonal = class_acc = None
    if tr.agent.conditional:
        conf = eval_confusion(tr, ck, out, seed=seed + 1)
        class_acc = {s: row[f"{tr.label} class acc"] for s, row in surv["table"].items()}
        diagonal = dict(zip(conf["skills"], conf["policy_diagonal"]))
    row = {
        "checkpoint": name,
        "samples": int(tr.agent.samples),
        "no_fall": no_fall,
        "diagonal": diagonal,
        "worst_no_fall": min(no_fall.values()),
        "min_diagonal": _lowest(diagonal),
        "class_acc": class_acc,  # argmax == command on the no-fall test's pairs (a confusion matrix's diagonal)
        "min_class_acc": _lowest(class_acc),
        "seed": seed,
        "settings": {"seconds": seconds, "k": k, "confusion_k": ck, "seed": seed},
    }
    return row


def _lowest(per_skill: dict[str, float] | None) -> float | None:
    """The lowest value over the skills (None for None: an AMP run's classifier numbers)."""
    return None if per_skill is None else min(per_skill.values())


# ---------------------------------------------------------------------------- the command's side
@dataclass
class CgailCheckpoints:
    """The settings of one `charctl eval RUN --checkpoints` (a `charctl.experiments.CheckpointEvaluation`)."""

    run_dir: Path
    out: Path
    device: str
    seconds: float
    k: int
    confusion_k: int
    fidelity: bool
    fidelity_k: int
    min_no_fall: float
    min_diagonal: float
    rank: str
    seed: int
    min_coverage: float
    confirm_seed: int
    conditional: bool = True  # False: an AMP run (no classifier, no diagonal)
    samples_key: str = "samples"  # the sample count in a checkpoint's state

    def check(self, name: str) -> None:
        """Load checkpoint `name` as `evaluate` does (its policy and discriminator, on the CPU)."""
        from charctl.experiments.cgail.policy import load_trained_run

        load_trained_run(self.run_dir, name)

    def evaluate(self, name: str, samples: int, out: Path, seed: int, confirm: bool = False) -> dict:
        row = evaluate_checkpoint(
            self.run_dir,
            name,
            samples,
            self.seconds,
            self.k,
            self.confusion_k,
            seed,
            out,
            fidelity_k=self.fidelity_k if self.fidelity else 0,
            filmstrips=confirm,
            device=self.device,
        )
        if not confirm and row["min_diagonal"] is not None:  # an AMP run has no margin (--rank fidelity only)
            row["margin"] = margin(row["worst_no_fall"], row["min_diagonal"], self.min_no_fall, self.min_diagonal)
        return row

    def rank_key(self, row: dict) -> tuple:
        return rank_key(row, self.rank, self.min_coverage)

    def write_report(self, rows: list[dict], chosen: dict, confirm: dict | None) -> str:
        return write_report(self.run_dir, rows, chosen, confirm, self)


def checkpoints(targets: list[str], options: dict, overrides: list[str]) -> CgailCheckpoints:
    """The `checkpoints` entry point: the settings of `--checkpoints`, every argument checked (one cgail run,
    no other mode but --survival / --fidelity, a known --rank, no classifier option for an AMP run, a
    machine that can draw the confirmation's filmstrips when fidelity is measured) before anything is written."""
    from charctl.eval.checkpoints import refuse_other_modes, single_run
    from charctl.experiments.cgail.policy import resolve_run_dirs
    from charctl.experiments.cgail.rollouts import split_eval_overrides
    from charctl.runs import read_run_config

    device, overrides = split_eval_overrides(overrides)
    run_dir = single_run(resolve_run_dirs(targets, overrides, "eval"), "cgail")
    measured = "no-fall (--survival SECONDS), the Fig 6.8 diagonal and fidelity (--fidelity)"
    refuse_other_modes(options, OTHER_MODES, measured)
    if options.get("checkpoint"):
        raise CharctlError("--checkpoints evaluates every kept checkpoint; --checkpoint names one (give either)")
    conditional = bool((read_run_config(run_dir).get("cgail") or {}).get("conditional", True))
    if not conditional:
        refuse_classifier_options(run_dir, options)
    rank = options.get("rank") or RANKS[0]
    if rank not in RANKS:
        raise CharctlError(f"--rank takes {' or '.join(RANKS)}, got {rank!r}")
    if rank != "fidelity" and options.get("min_coverage") is not None:
        raise CharctlError("--min-coverage is a rule of --rank fidelity; --rank margin does not count coverage")
    fidelity = bool(options.get("fidelity")) or rank == "fidelity"
    if fidelity:
        from charctl.experiments.cgail.fidelity import check_can_render

        check_can_render()  # the chosen checkpoint's filmstrips

    def pick(name: str, default):
        return default if options.get(name) is None else options[name]

    return CgailCheckpoints(
        run_dir=run_dir,
        out=Path(options.get("out") or run_dir / "eval"),
        device=device or "cpu",
        seconds=float(pick("survival", SECONDS)),
        k=int(pick("episodes", EPISODES)),
        confusion_k=int(pick("confusion_k", CONFUSION_EPISODES)),
        fidelity=fidelity,
        fidelity_k=int(pick("fidelity_k", FIDELITY_EPISODES)),
        min_no_fall=float(pick("min_no_fall", MIN_NO_FALL)),
        min_diagonal=float(pick("min_diagonal", MIN_DIAGONAL)),
        rank=rank,
        seed=int(pick("seed", SEED)),
        min_coverage=float(pick("min_coverage", MIN_COVERAGE)),
        confirm_seed=int(pick("confirm_seed", CONFIRM_SEED)),
        conditional=conditional,
    )


def refuse_classifier_options(run_dir: Path, options: dict) -> None:
    """A one-line error for an option of the Fig 6.8 diagonal (--rank margin, --confusion-k, --min-diagonal)
    given for an AMP (unconditional) run, which has no classifier; it is ranked by fidelity."""
    asked = ["--rank margin"] if options.get("rank") == "margin" else []
    asked += ["--" + o.replace("_", "-") for o in CLASSIFIER_OPTIONS if options.get(o) is not None]
    if asked:
        raise CharctlError(
            f"{run_dir} is an AMP (unconditional) run: it has no classifier for the Fig 6.8 diagonal that "
            f"{asked[0]} needs; its checkpoints are ranked by fidelity (--rank fidelity)"
        )
