"""The genetic algorithm (paper §4) with DEAP operators: tournament selection, simulated-binary
crossover and polynomial mutation inside the gene bounds, and elitism.

Minimisation of eval(gamma, E) (eq 14). Physically impossible individuals get eval = inf and
are never selected as parents (paper §4.1: "removed from the competition"); generation 0
re-draws them (up to ga.init_retries rounds) so the first population is fully valid.

DEAP draws from Python's `random` module; it is seeded with cfg.seed at the start of a run and
its state is stored in every checkpoint, so `--resume` continues the exact same trajectory.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from charctl.errors import CharctlError

HISTORY_KEYS = ("best", "mean", "valid_fraction", "gamma", "E_r", "E", "best_so_far", "eval_s")


def _deap():
    from deap import algorithms, base, tools

    class FitnessMin(base.Fitness):
        weights = (-1.0,)

    class Individual(list):
        def __init__(self, genes=()):
            super().__init__(genes)
            self.fitness = FitnessMin()

    return algorithms, base, tools, Individual


@dataclass
class GAState:
    generation: int  # generations completed (0 = the initial population is evaluated)
    population: np.ndarray  # (N, G)
    fitness: np.ndarray  # (N,)
    random_state: tuple
    history: dict[str, list[float]] = field(default_factory=lambda: {k: [] for k in HISTORY_KEYS})
    best_genome: np.ndarray | None = None  # best ever (hall of fame)
    best_fitness: float = float("inf")
    eval_seconds: float = 0.0
    evaluations: int = 0

    # ------------------------------------------------------------ checkpoint (weights_only-loadable)
    def to_checkpoint(self) -> dict:
        import torch

        version, internal, gauss = self.random_state
        return {
            "generation": int(self.generation),
            "population": torch.from_numpy(np.ascontiguousarray(self.population)),
            "fitness": torch.from_numpy(np.ascontiguousarray(self.fitness)),
            "random_state": [int(version), [int(v) for v in internal], gauss],
            "history": {k: [float(v) for v in vals] for k, vals in self.history.items()},
            "best_genome": torch.from_numpy(np.ascontiguousarray(self.best_genome)),
            "best_fitness": float(self.best_fitness),
            "eval_seconds": float(self.eval_seconds),
            "evaluations": int(self.evaluations),
        }

    @classmethod
    def from_checkpoint(cls, d: dict) -> GAState:
        version, internal, gauss = d["random_state"]
        return cls(
            generation=int(d["generation"]),
            population=d["population"].numpy().astype(float),
            fitness=d["fitness"].numpy().astype(float),
            random_state=(int(version), tuple(int(v) for v in internal), gauss),
            history={k: list(v) for k, v in d["history"].items()},
            best_genome=d["best_genome"].numpy().astype(float),
            best_fitness=float(d["best_fitness"]),
            eval_seconds=float(d["eval_seconds"]),
            evaluations=int(d["evaluations"]),
        )


class GeneticAlgorithm:
    """The GA one generation at a time: `start(state)` evaluates the initial population (generation 0)
    or re-opens a checkpoint's, then each `step()` breeds and evaluates one generation. `state` is the
    GAState (checkpoint) after the last call; both calls return the best individual's metrics."""

    def __init__(self, ga_cfg, seed: int, low: np.ndarray, high: np.ndarray, evaluate: Callable[[np.ndarray], dict]):
        algorithms, base, tools, Individual = _deap()
        self.algorithms, self.tools, self.Individual = algorithms, tools, Individual
        self.ga_cfg, self.seed, self.evaluate = ga_cfg, int(seed), evaluate
        self.N, self.G = int(ga_cfg.population), len(low)
        self.lo, self.hi = [float(v) for v in low], [float(v) for v in high]
        lo, hi = self.lo, self.hi
        toolbox = base.Toolbox()
        toolbox.register("mate", tools.cxSimulatedBinaryBounded, eta=float(ga_cfg.cx_eta), low=lo, up=hi)
        toolbox.register(
            "mutate", tools.mutPolynomialBounded, eta=float(ga_cfg.mut_eta), low=lo, up=hi, indpb=float(ga_cfg.indpb)
        )
        toolbox.register("select", tools.selTournament, tournsize=int(ga_cfg.tournament))
        self.toolbox = toolbox
        self.state: GAState | None = None
        self.pop: list = []
        self.metrics: dict = {}

    def _eval(self, genomes: np.ndarray) -> dict:
        t0 = time.perf_counter()
        out = self.evaluate(np.asarray(genomes, dtype=float))
        self.state.eval_seconds += time.perf_counter() - t0
        self.state.evaluations += len(genomes)
        return out

    def _random_individual(self):
        return self.Individual(random.uniform(a, b) for a, b in zip(self.lo, self.hi))

    def start(self, state: GAState | None = None) -> dict | None:
        """Generation 0 (random, invalid individuals re-drawn), or the population of `state` (a resumed
        run: its per-individual metrics are re-evaluated, which is deterministic). Returns the best
        individual's metrics of generation 0, None on a resume."""
        N, G, ga_cfg = self.N, self.G, self.ga_cfg
        if state is not None:
            if state.population.shape != (N, G):
                raise CharctlError(f"checkpoint population is {state.population.shape}, this config needs ({N}, {G})")
            self.state = state
            random.setstate(state.random_state)
            self.pop = [self.Individual(row.tolist()) for row in state.population]
            self.metrics = self._eval(state.population)  # deterministic: re-creates the per-individual metrics
            _assign(self.pop, state.fitness)
            return None
        random.seed(self.seed)
        self.state = GAState(
            generation=0, population=np.zeros((N, G)), fitness=np.zeros(N), random_state=random.getstate()
        )
        pop = [self._random_individual() for _ in range(N)]
        metrics = self._eval(np.array(pop))
        for _ in range(int(ga_cfg.init_retries)):
            bad = np.flatnonzero(~metrics["valid"])
            if len(bad) == 0:
                break
            for i in bad:
                pop[i] = self._random_individual()
            redo = self._eval(np.array([pop[i] for i in bad]))
            for k in metrics:
                metrics[k][bad] = redo[k]
        if not metrics["valid"].any():
            raise CharctlError(
                f"no physically valid individual in {N} x {int(ga_cfg.init_retries) + 1} "
                "random draws; widen the bounds (see `charctl config hopper-ga`)"
            )
        _assign(pop, metrics["fitness"])
        self.pop, self.metrics = pop, metrics
        _record(self.state, pop, metrics)
        return _best_metrics(pop, metrics)

    def step(self) -> dict:
        """One generation: tournament selection, crossover and mutation, elitism; returns the best's metrics."""
        ga_cfg, tools, toolbox, pop = self.ga_cfg, self.tools, self.toolbox, self.pop
        valid = [ind for ind in pop if np.isfinite(ind.fitness.values[0])]
        best = tools.selBest(valid, int(ga_cfg.elite))
        elite_rows = [_row_of(pop, e) for e in best]
        elites = [toolbox.clone(ind) for ind in best]
        offspring = [toolbox.clone(ind) for ind in toolbox.select(valid, self.N - len(elites))]
        offspring = self.algorithms.varAnd(offspring, toolbox, float(ga_cfg.cxpb), float(ga_cfg.mutpb))
        fresh = [i for i, ind in enumerate(offspring) if not ind.fitness.valid]
        new = self._eval(np.array([offspring[i] for i in fresh])) if fresh else None
        if new is not None:
            _assign([offspring[i] for i in fresh], new["fitness"])
        # per-individual metrics of the next population: elites keep theirs, unchanged offspring too
        pop_next = elites + offspring
        self.metrics = _gather_metrics(pop_next, elite_rows, offspring, fresh, new, self.metrics, pop)
        self.pop = pop_next
        self.state.generation += 1
        _record(self.state, self.pop, self.metrics)
        return _best_metrics(self.pop, self.metrics)


def evolve(
    ga_cfg,
    seed: int,
    low: np.ndarray,
    high: np.ndarray,
    evaluate: Callable[[np.ndarray], dict],
    state: GAState | None = None,
) -> GAState:
    """Run (or continue from `state`) the GA up to ga_cfg.generations in one go (tests, benchmarks;
    `charctl train` steps the same GeneticAlgorithm through the shared runner, charctl.rl.runner)."""
    ga = GeneticAlgorithm(ga_cfg, seed, low, high, evaluate)
    ga.start(state)
    while ga.state.generation < int(ga_cfg.generations):
        ga.step()
    return ga.state


# ---------------------------------------------------------------------------- helpers
def _assign(inds, fitness: np.ndarray) -> None:
    for ind, f in zip(inds, fitness):
        ind.fitness.values = (float(f),)


def _row_of(pop, ind) -> int:
    return next(i for i, p in enumerate(pop) if p is ind)


def _gather_metrics(pop_next, elite_rows, offspring, fresh, new, old, pop_old) -> dict:
    """Metrics rows for pop_next without re-evaluating unchanged individuals."""
    keys = list(old.keys())
    out = {k: np.empty((len(pop_next),) + old[k].shape[1:], dtype=old[k].dtype) for k in keys}
    for r, src in enumerate(elite_rows):
        for k in keys:
            out[k][r] = old[k][src]
    index_old = {tuple(p): i for i, p in enumerate(pop_old)}
    fresh_pos = {i: j for j, i in enumerate(fresh)}
    base = len(elite_rows)
    for i, ind in enumerate(offspring):
        if i in fresh_pos:
            for k in keys:
                out[k][base + i] = new[k][fresh_pos[i]]
        else:  # an unmodified copy of a parent
            src = index_old[tuple(ind)]
            for k in keys:
                out[k][base + i] = old[k][src]
    return out


def _best_metrics(pop, metrics: dict) -> dict:
    i = int(np.argmin(metrics["fitness"]))
    return {k: (v[i].item() if np.ndim(v[i]) == 0 else v[i]) for k, v in metrics.items()} | {
        "genome": np.array(pop[i], dtype=float)
    }


def _record(st: GAState, pop, metrics: dict) -> None:
    fit = metrics["fitness"]
    st.population = np.array(pop, dtype=float)
    st.fitness = np.asarray(fit, dtype=float).copy()
    st.random_state = random.getstate()
    i = int(np.argmin(fit))
    if fit[i] < st.best_fitness:
        st.best_fitness = float(fit[i])
        st.best_genome = st.population[i].copy()
    finite = np.isfinite(fit)
    h = st.history
    h["best"].append(float(fit[i]))
    h["mean"].append(float(fit[finite].mean()) if finite.any() else float("nan"))
    h["valid_fraction"].append(float(finite.mean()))
    h["gamma"].append(float(metrics["gamma"][i]))
    h["E_r"].append(float(metrics["E_r"][i]))
    h["E"].append(float(metrics["E"][i]))
    h["best_so_far"].append(float(st.best_fitness))
    h["eval_s"].append(float(st.eval_seconds))
