"""Running many trainings at once: multirun jobs on Ray (`charctl train EXP -m ... --launcher ray`) and
hyper-parameter search on Ray Tune (`charctl tune EXP key=choice(...) ...`).

Every job or trial is a plain `python -m charctl.cli train EXP overrides...` subprocess, so signals,
checkpoints, exit codes and one-line errors behave exactly as on the command line:

    search_space.py  `choice(a,b)` / `range(lo,hi)` / `loguniform(lo,hi)` override values (no Ray needed)
    job.py           one training as a child process: start, interrupt (SIGINT -> checkpoint), outcome
    cluster.py       connect to a Ray cluster or start a local instance sized to this machine
    table.py         the driver's live table of job states
    ray_jobs.py      multirun jobs as Ray actors with declared CPUs / GPUs
    tune.py          Ray Tune + ASHA over a child training's streamed scalars; table, plot, best.yaml

Nothing here is imported by `charctl --help`; Ray is imported only inside these modules' functions.
"""
