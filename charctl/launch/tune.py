"""`charctl tune`: random search over `choice / range / loguniform` overrides on Ray Tune, with ASHA
stopping the trials that trail the others.

Each trial is a `charctl train EXP overrides...` child process (charctl.launch.job) whose run streams
every scalar set it logs (`charctl.runs.METRICS_STREAM_ENV`, one JSON line per `Run.log_scalars`
call, then its metrics.json numbers). The trial reports one result to Tune per logged value of the
metric, so every experiment reports at its own natural pace (PPO iterations, GA generations,
evaluation steps) without knowing about Tune. ASHA stops a trial by stopping its Trainable, whose
`cleanup` sends the child one SIGINT: it writes its checkpoint and exits like a Ctrl-C'd run.

Output, under `<output_root>/tune/<EXP>/<timestamp>/`:
    runs/<EXP>/<run>/   every trial's run directory (config.yaml, tb/, checkpoints/, job.log ...)
    logs/<trial id>/    each trial's stdout, stderr and exit code as its child wrote them
    trials.md|csv|json  one row per trial, best first: state, sampled values, metric, reports, run
    tune.png            the metric against each searched key (hollow: stopped early by ASHA)
    best.yaml           the best trial's overrides as `key: value` lines, with the command line to rerun it
    ray/                Ray Tune's own records

This module drives the search (`run_tune`); the trial types are in `tune_setup.py`, the Trainable in
`tune_trial.py`, the live table in `tune_view.py`, the result files in `tune_outputs.py`.
"""

from __future__ import annotations

import os
import signal
from datetime import datetime
from pathlib import Path

from charctl.errors import CharctlError, Interrupted
from charctl.launch.tune_outputs import write_outputs
from charctl.launch.tune_setup import BIG_T, TrialRecord, TuneSetup
from charctl.launch.tune_trial import trial_class, trial_dirname, wait_for_children
from charctl.launch.tune_view import StopRequest, TuneView, tune_callback


# ---------------------------------------------------------------------------- driver
def run_tune(setup: TuneSetup) -> tuple[list[TrialRecord], TrialRecord | None]:
    """Run the search; write the tables, the plot and best.yaml into `setup.out_dir`."""
    from charctl.launch.cluster import cluster_summary, import_tune, ray_session
    from charctl.launch.table import JobTable

    tune = import_tune()
    out = Path(setup.out_dir)
    labels = ["(not sampled yet)"] * setup.settings.trials
    stop = StopRequest()
    with ray_session(setup.settings.address, "charctl tune") as ray:
        print(
            f"tune {setup.experiment}: {setup.settings.trials} trial(s), {setup.metric} ({setup.mode}), ASHA; "
            f"Ray: {cluster_summary(ray)}; {setup.settings.cpus:g} CPU per trial -> {out}"
        )
        os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")  # Tune's own progress tables off (verbose=0): ours instead
        columns = (setup.metric, "reports")
        with JobTable(f"tune {setup.experiment}", labels, extra_columns=columns, final_table=False) as table:
            view = TuneView(setup, table, stop)
            tuner = _make_tuner(tune, setup, view, out)
            with stop.installed():
                try:
                    tuner.fit()
                except KeyboardInterrupt:  # a second Ctrl-C: Tune gave up on the graceful stop
                    stop.signum = stop.signum or int(signal.SIGINT)
            _settle_final_states(view)
    wait_for_children(setup, list(view.records))
    records = sorted(view.records.values(), key=lambda r: r.number)
    best = write_outputs(setup, records)
    if stop.signum:
        raise Interrupted(f"interrupted: the trials so far, with their checkpoints, are in {out}", signum=stop.signum)
    return records, best


def _make_tuner(tune, setup: TuneSetup, view: TuneView, out: Path):
    """The `tune.Tuner`: random search (seeded) with ASHA, one CharctlTrial per sample, Tune's records
    under `out/ray/`, no Tune checkpoints (each child run writes its own) and no retries."""
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.basic_variant import BasicVariantGenerator

    trainable = tune.with_resources(
        tune.with_parameters(trial_class(), setup=setup),
        {"cpu": setup.settings.cpus, "gpu": setup.settings.gpus},
    )
    return tune.Tuner(
        trainable,
        param_space={d.name: d.to_tune() for d in setup.dims},
        tune_config=tune.TuneConfig(
            metric=setup.metric,
            mode=setup.mode,
            num_samples=setup.settings.trials,
            scheduler=ASHAScheduler(
                max_t=setup.settings.max_reports or BIG_T,
                grace_period=setup.settings.grace_period,
                reduction_factor=4,
            ),
            search_alg=BasicVariantGenerator(random_state=setup.settings.seed),
            trial_dirname_creator=trial_dirname,
        ),
        run_config=tune.RunConfig(
            name="ray",
            storage_path=str(out),
            verbose=0,
            callbacks=[tune_callback(view)],
            failure_config=tune.FailureConfig(max_failures=0),
            checkpoint_config=tune.CheckpointConfig(checkpoint_frequency=0, checkpoint_at_end=False),
        ),
    )


def _settle_final_states(view: TuneView) -> None:
    """Record the states Tune settled after the last callback (errored or terminated trials still
    shown as pending/running)."""
    for trial_id, rec in view.records.items():
        if rec.state in ("pending", "running"):
            trial = view.trials[trial_id]
            if trial.status == "ERROR":
                view.errored(trial)
            elif trial.status == "TERMINATED":
                view.completed(trial)


def make_out_dir(output_root: str | Path, experiment: str) -> Path:
    """`<output_root>/tune/<experiment>/<timestamp>/` (absolute; `_1`, `_2` ... when taken)."""
    from charctl.paths import make_unique_dir

    root = Path(output_root).expanduser().resolve() / "tune" / experiment
    try:
        return make_unique_dir(root, datetime.now().strftime("%Y-%m-%d_%H-%M-%S"))
    except OSError as exc:
        raise CharctlError(f"cannot create the tune folder in {root}: {exc.strerror or exc}") from None
