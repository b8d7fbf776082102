"""`charctl train hopper-ga [speed=5 beta=0.5 runtime.kind=ray ...]`: the GA on the shared runner
(charctl.rl.runner: stop signals, progress, checkpoints, --resume, divergence check, metrics), one
iteration per generation and the evaluations as its samples; the run's outputs at the end (and on a stop)."""

from __future__ import annotations

import numpy as np

from charctl.experiments.hopper_ga.ga import GAState, GeneticAlgorithm
from charctl.experiments.hopper_ga.runtime import make_evaluator
from charctl.experiments.hopper_ga.settings import settings_from_config


def ga_signature(cfg, settings) -> dict:
    """What a checkpoint must match to load into this config's GA: the genome length and the population size."""
    return {"genes": len(settings.low), "population": int(cfg.ga.population)}


class GaLearner:
    """One generation of the GA for the shared runner. Generation 0 (the random initial population) is
    evaluated in the first iteration, before generation 1, so `iteration` counts generations
    (GAState.generation) and `samples` counts evaluations (GAState.evaluations)."""

    def __init__(self, cfg, run, settings, evaluate):
        self.cfg, self.run, self.s = cfg, run, settings
        self.ga = GeneticAlgorithm(cfg.ga, int(cfg.seed), settings.low, settings.high, evaluate)
        self.iteration = 0
        self.samples = 0
        self.samples_per_iteration = 0  # this generation's evaluations (elites and unchanged copies are not re-run)
        self.resume_from: GAState | None = None

    @property
    def state(self) -> GAState:
        return self.ga.state

    def signature(self) -> dict:
        return ga_signature(self.cfg, self.s)

    def modules(self) -> list:
        return []

    def state_dict(self) -> dict:
        return self.state.to_checkpoint()

    def load_state_dict(self, state: dict) -> None:
        self.resume_from = GAState.from_checkpoint(state)
        self.iteration, self.samples = self.resume_from.generation, self.resume_from.evaluations

    def iterate(self) -> dict[str, float]:
        before = self.samples
        if self.ga.state is None:  # the run's first iteration: generation 0, or the checkpoint's population
            best = self.ga.start(self.resume_from)
            if best is not None:  # generation 0's point in TensorBoard (the runner logs generations 1, 2, ...)
                self.run.log_scalars(self._scalars(best), self.state.evaluations)
        best = self.ga.step()
        self.samples_per_iteration = self.state.evaluations - before
        return self._scalars(best)

    def _scalars(self, best: dict) -> dict[str, float]:
        h = self.state.history
        return {
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
        }

    def progress_fields(self, stats: dict[str, float]) -> dict[str, float]:
        return {"eval": stats["fitness/best"], "gamma": stats["best/gamma"], "E_r": stats["best/E_r"]}

    def summary(self, stats: dict[str, float]) -> dict:  # noqa: ARG002
        """best_genome.json, the figures and the gait / limp numbers of the best genome so far."""
        from charctl.experiments.hopper_ga.results import write_outputs

        cfg, s, st = self.cfg, self.s, self.state
        outputs = write_outputs(self.run.dir, st.history, st.best_genome, s, cfg)
        return {
            "speed": s.speed,
            "beta": s.beta,
            "generations_done": st.generation,
            "finished": st.generation >= int(cfg.ga.generations),
            "best_eval": st.best_fitness,
            **{k: v for k, v in outputs["gait"].items() if k != "eval"},
            "runtime": str(cfg.runtime.kind),
            "workers": int(cfg.runtime.workers),
            "eval_wall_s": st.eval_seconds,
            "evaluations": st.evaluations,
            "limp": outputs["limp"],
            "best_genome": dict(zip(s.gene_names, np.round(st.best_genome, 6).tolist())),
        }


def train(cfg, run) -> dict:
    """Evolve into `run` with the shared runner; returns the headline numbers (the `done:` line)."""
    from charctl.rl.runner import RunnerSettings, run_on_policy

    s = settings_from_config(cfg)
    settings = RunnerSettings(
        total_iterations=int(cfg.ga.generations),
        budget_key="ga.generations",
        iteration_name="generation",
        bar_unit="gen",
        checkpoint_every=int(cfg.train.checkpoint_every),
        keep_every=int(cfg.train.keep_checkpoint_every),
        description="hopper-ga",
        track_blowups=False,
    )
    with make_evaluator(cfg.runtime, s) as evaluate:
        metrics = run_on_policy(GaLearner(cfg, run, s, evaluate), run, settings)
    return {
        k: metrics[k]
        for k in ("best_eval", "gamma", "E_r", "step_length_m", "flight_time_s", "cadence_spm", "wall_s", "runtime")
    }
