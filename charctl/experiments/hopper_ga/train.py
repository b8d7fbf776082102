"""`charctl train hopper-ga [speed=5 beta=0.5 runtime.kind=ray ...]`: the GA loop with a
checkpoint per generation, TensorBoard scalars, and the run's outputs at the end."""

from __future__ import annotations

import time

import numpy as np

from charctl.experiments.hopper_ga.ga import GAState, evolve
from charctl.experiments.hopper_ga.model import settings_from_config
from charctl.experiments.hopper_ga.runtime import make_evaluator


def train(cfg, run) -> dict:
    from charctl.progress import TrainingProgress
    from charctl.signals import StopFlag

    s = settings_from_config(cfg)
    signature = {"genes": len(s.low), "population": int(cfg.ga.population)}
    state = GAState.from_checkpoint(run.load_checkpoint(signature)) if run.resumed else None
    start_gen = state.generation if state is not None else 0
    generations = int(cfg.ga.generations)
    run.writer  # noqa: B018  create the TensorBoard writer (imports torch) before the GA clock starts
    t0 = time.perf_counter()

    with (
        make_evaluator(cfg.runtime, s) as evaluate,
        StopFlag() as stop,
        TrainingProgress(generations, "hopper-ga", "gen") as bar,
    ):
        bar.update(start_gen)

        def on_generation(st: GAState, best: dict) -> None:
            g = st.generation
            h = st.history
            run.log_scalars(
                {
                    "fitness/best": h["best"][-1],
                    "fitness/mean": h["mean"][-1],
                    "fitness/best_so_far": h["best_so_far"][-1],
                    "fitness/valid_fraction": h["valid_fraction"][-1],
                    "best/gamma": h["gamma"][-1],
                    "best/E_r": h["E_r"][-1],
                    "best/E": h["E"][-1],
                    "best/stance_time": best["stance_time"],
                    "best/flight_time": best["flight_time"],
                    "best/step_length": best["step_length"],
                },
                step=g,
            )
            run.save_checkpoint(st.to_checkpoint(), signature)
            if g > start_gen:
                bar.update(1, eval=h["best"][-1], gamma=h["gamma"][-1], E_r=h["E_r"][-1])

        state = evolve(cfg.ga, int(cfg.seed), s.low, s.high, evaluate, state, on_generation, lambda: stop.requested)
    wall = time.perf_counter() - t0

    from charctl.experiments.hopper_ga.results import write_outputs

    outputs = write_outputs(run.dir, state.history, state.best_genome, s, cfg)
    finished = state.generation >= generations
    metrics = {
        "speed": s.speed,
        "beta": s.beta,
        "generations_done": state.generation,
        "finished": finished,
        "best_eval": state.best_fitness,
        **{k: v for k, v in outputs["gait"].items() if k != "eval"},
        "runtime": str(cfg.runtime.kind),
        "workers": int(cfg.runtime.workers),
        "wall_s": wall,
        "eval_wall_s": state.eval_seconds,
        "evaluations": state.evaluations,
        "limp": outputs["limp"],
        "best_genome": dict(zip(s.gene_names, np.round(state.best_genome, 6).tolist())),
    }
    run.write_metrics(metrics)
    if stop.requested:  # Ctrl-C / SIGTERM: the generation's checkpoint and the outputs so far are written
        raise stop.interrupted(
            f"interrupted at generation {state.generation}/{generations}: checkpoint written; "
            f"continue with --resume {run.dir}"
        )
    return {
        k: metrics[k]
        for k in ("best_eval", "gamma", "E_r", "step_length_m", "flight_time_s", "cadence_spm", "wall_s", "runtime")
    }
