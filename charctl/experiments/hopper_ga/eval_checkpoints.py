"""`charctl eval RUN --checkpoints [--after N] [-o DIR] [overrides]` for hopper-ga: every kept checkpoint
(checkpoints/samples_<n>.pt, train.keep_checkpoint_every, n in evaluations; and last.pt) ranked by its best
individual's fitness (the loop and the files: charctl/commands/eval_checkpoints.py and
charctl/eval/checkpoints.py).

The best individual is the checkpoint's hall of fame (`best_genome`, the best genome found up to that
generation). Its fitness is re-evaluated, not read back: `results.gait_summary` runs the experiment's own
evaluation (`model.evaluate_genomes`, eq 12-14) on that one genome, which takes milliseconds, so every
checkpoint is also measured while the arguments are checked (an impossible genome, e.g. under a `speed=`
override, is refused before anything is written). The lowest eval wins (the GA minimises it); the table
also lists the fitness stored in the checkpoint (equal unless overrides change the model), the generation,
gamma and E_r. Elitism keeps the best so far, so later checkpoints are never worse under the run's own
settings: the choice is the first checkpoint that reached the final best. Deterministic (no starts drawn),
so the chosen checkpoint is not evaluated again. Writes OUT/checkpoints.{json,md,png} and
OUT/<checkpoint>/row.json (OUT: -o, default RUN/eval/).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

from charctl.eval.checkpoints import Metric, ScalarCheckpoints, refuse_other_modes, single_run

OTHER_MODES = ("curves",)  # evaluation modes --checkpoints does not combine with
MODEL_KEYS = ("speed", "beta", "hopper", "character", "balance", "bounds", "fitness")  # what the fitness depends on
METRIC = Metric(
    key="eval",
    label="best eval",
    lower_is_better=True,
    note=(
        "Best eval: the fitness (eq 14, dimensionless, 0 best) of the checkpoint's best genome so far (its hall of "
        "fame), re-evaluated by the model (`results.gait_summary`); stored: the value the checkpoint holds; "
        "E_r in units of `fitness.energy_scale`."
    ),
    columns=(("stored_eval", "stored eval"), ("generation", "generation"), ("gamma", "gamma"), ("E_r", "E_r")),
)


def checkpoints(targets: list[str], options: dict, overrides: list[str]) -> ScalarCheckpoints:
    """The `checkpoints` entry point: one hopper-ga run, no other evaluation mode; every argument is checked
    before anything is written."""
    from omegaconf import OmegaConf

    from charctl.experiments.hopper_ga.results import open_hopper_run, run_dirs
    from charctl.experiments.hopper_ga.train import ga_signature

    refuse_other_modes(options, OTHER_MODES, "the best individual's fitness (eq 14)")
    run_dir = single_run(run_dirs(targets, overrides), "hopper-ga")
    run, settings = open_hopper_run(run_dir, overrides)
    cfg = OmegaConf.to_container(run.cfg, resolve=True)
    return ScalarCheckpoints(
        run_dir=run_dir,
        out=Path(options.get("out") or run_dir / "eval"),
        experiment="hopper-ga",
        metric=METRIC,
        measure=partial(best_fitness, settings),
        signature=ga_signature(run.cfg, settings),
        settings={k: cfg[k] for k in MODEL_KEYS},
        samples_key="evaluations",  # the GA's samples (GAState.evaluations)
        samples_label="evaluations",
        cheap=True,
    )


def best_fitness(settings, state: dict) -> dict:
    """The re-evaluated fitness ("eval", dimensionless), gamma and E_r (units of fitness.energy_scale) of
    checkpoint `state`'s best genome, the fitness it stores and its generation."""
    from charctl.experiments.hopper_ga.results import gait_summary

    genome = state["best_genome"].numpy().astype(float)
    gait = gait_summary(genome, settings)
    return {
        "eval": gait["eval"],
        "stored_eval": float(state["best_fitness"]),
        "generation": int(state["generation"]),
        "gamma": gait["gamma"],
        "E_r": gait["E_r"],
    }
