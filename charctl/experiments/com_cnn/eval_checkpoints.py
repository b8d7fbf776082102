"""`charctl eval RUN --checkpoints [--after N] [-o DIR] [overrides]` for com-cnn: every kept checkpoint
(checkpoints/samples_<n>.pt, train.keep_checkpoint_every, n in training windows seen; and last.pt) ranked
by its held-out pose error (the loop and the files: charctl/commands/eval_checkpoints.py and
charctl/eval/checkpoints.py).

The number is `charctl eval RUN --pose-error`'s teacher-forced error (`evaluate.teacher_forced_errors`,
paper Table 5): the mean joint-angle error in degrees over the movable joints and every window of the
held-out clips (data.test_clips), history and C_t from the ground truth. The lowest wins; the table also
lists it per paper motion type. It is deterministic (no starts drawn), so the chosen checkpoint is not
evaluated again. Writes OUT/checkpoints.{json,md,png} and OUT/<checkpoint>/row.json (OUT: -o, default
RUN/eval/; a row is reused while the checkpoint and the run's data settings are unchanged).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from charctl.errors import CharctlError
from charctl.eval.checkpoints import Metric, ScalarCheckpoints, refuse_other_modes, single_run

OTHER_MODES = ("pose_error", "dtw")  # evaluation modes --checkpoints does not combine with
METRIC_KEY = "pose_error_deg"


def checkpoints(targets: list[str], options: dict, overrides: list[str]) -> ScalarCheckpoints:
    """The `checkpoints` entry point: one com-cnn run with held-out clips, no other evaluation mode; its
    data are loaded and every argument is checked before anything is written."""
    from omegaconf import OmegaConf

    from charctl.experiments.com_cnn.checkpoint import open_com_cnn_run, resolve_targets
    from charctl.experiments.com_cnn.model import model_signature
    from charctl.experiments.com_cnn.sequences import load_sequences, motion_type, split_sequences

    refuse_other_modes(options, OTHER_MODES, "the held-out pose error (--pose-error's teacher-forced error)")
    run_dir = single_run(resolve_targets(targets, overrides), "com-cnn")
    run = open_com_cnn_run(run_dir, overrides)
    seqs, body = load_sequences(run.cfg)
    _, test_seqs = split_sequences(seqs, run.cfg.data.test_clips)
    if not test_seqs:
        raise CharctlError("no held-out clips (data.test_clips is empty): nothing to rank the checkpoints by")
    types = {str(k): list(v) for k, v in run.cfg.eval.motion_types.items()}
    kinds = sorted({motion_type(s.label, types) for s in test_seqs})
    return ScalarCheckpoints(
        run_dir=run_dir,
        out=Path(options.get("out") or run_dir / "eval"),
        experiment="com-cnn",
        metric=_metric(test_seqs, kinds),
        measure=partial(held_out_pose_error, run_dir, run.cfg, body, test_seqs, types),
        signature=model_signature(run.cfg, body.pose_dim),
        settings={"data": OmegaConf.to_container(run.cfg.data, resolve=True), "motion_types": types},
        samples_label="training windows",
    )


def held_out_pose_error(run_dir: Path, cfg, body, test_seqs: list, types: dict, state: dict) -> dict:
    """The teacher-forced joint-angle error (degrees) of checkpoint `state` on the held-out clips: overall
    (METRIC_KEY), per motion type ("<type>_deg"), and the number of windows it is averaged over."""
    from charctl.experiments.com_cnn.checkpoint import LoadedRun, model_from_state
    from charctl.experiments.com_cnn.evaluate import teacher_forced_errors

    network = LoadedRun(run_dir, cfg, model_from_state(cfg, body.pose_dim, state), body, test_seqs, {})
    err = teacher_forced_errors(network.predictor(), test_seqs, body, types)
    per_type = {f"{kind}_deg": value for kind, value in err["per_type"].items()}
    return {METRIC_KEY: err["all"], **per_type, "windows": err["frames"]}


def _metric(test_seqs: list, kinds: list[str]) -> Metric:
    """The held-out pose error as `ScalarCheckpoints` ranks and shows it (per motion type of the held-out clips)."""
    clips = ", ".join(s.name for s in test_seqs)
    return Metric(
        key=METRIC_KEY,
        label="held-out pose error (deg)",
        lower_is_better=True,
        note=(
            "Held-out pose error: `charctl eval RUN --pose-error`'s teacher-forced error (paper Table 5), the mean "
            "joint-angle error in degrees over the movable joints and every window of the held-out clips "
            f"({clips}), history and C_t from the ground truth; per paper motion type in the further columns."
        ),
        columns=(*((f"{k}_deg", f"{k} (deg)") for k in kinds), ("windows", "windows")),
    )
