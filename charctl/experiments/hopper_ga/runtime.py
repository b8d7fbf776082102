"""Population evaluation back-ends (`runtime.kind`): local | process | ray.

Each back-end splits the (N, G) genome batch into `runtime.workers` contiguous chunks (local:
one chunk) and evaluates every chunk with the same vectorised numpy function,
`model.evaluate_genomes`, whose row results never depend on the other rows of the batch. So the
three back-ends return bit-identical fitness values, and the GA (which runs in the driver with
one seeded random stream) follows the same trajectory for the same seed.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.hopper_ga.model import evaluate_genomes
from charctl.experiments.hopper_ga.settings import Settings


def _split(genomes: np.ndarray, parts: int) -> list[np.ndarray]:
    chunks = np.array_split(np.asarray(genomes, dtype=float), max(1, min(parts, len(genomes))))
    return [np.ascontiguousarray(c) for c in chunks if len(c)]


def _merge(results: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([r[k] for r in results]) for k in results[0]}


def _eval_chunk(settings: Settings, chunk: np.ndarray) -> dict[str, np.ndarray]:
    """Top-level (picklable) worker function."""
    return evaluate_genomes(chunk, settings)


class LocalEvaluator:
    """The whole population in one vectorised call in this process (default)."""

    name = "local"

    def __init__(self, settings: Settings, workers: int = 1, address: str = "") -> None:  # noqa: ARG002
        self.settings = settings

    def __call__(self, genomes: np.ndarray) -> dict[str, np.ndarray]:
        return evaluate_genomes(np.ascontiguousarray(genomes, dtype=float), self.settings)

    def close(self) -> None:
        pass


class ProcessEvaluator:
    """A multiprocessing pool (spawn context: workers import only numpy and this package)."""

    name = "process"

    def __init__(self, settings: Settings, workers: int = 2, address: str = "") -> None:  # noqa: ARG002
        import multiprocessing as mp

        self.settings = settings
        self.workers = workers
        self.pool = mp.get_context("spawn").Pool(processes=workers)

    def __call__(self, genomes: np.ndarray) -> dict[str, np.ndarray]:
        chunks = _split(genomes, self.workers)
        return _merge(self.pool.starmap(_eval_chunk, [(self.settings, c) for c in chunks]))

    def close(self) -> None:
        self.pool.close()
        self.pool.join()


class RayEvaluator:
    """Ray tasks: `ray.init()` on this machine by default (num_cpus = workers), or connect to
    `runtime.address` (e.g. "auto" or "ray://head:10001") so a sweep or a large population
    spreads over a cluster."""

    name = "ray"

    def __init__(self, settings: Settings, workers: int = 2, address: str = "") -> None:
        try:
            import ray
        except ImportError:
            raise CharctlError(
                "runtime.kind=ray needs Ray: pip install 'ray>=2.40' (or `pip install charctl[ray]`)"
            ) from None
        self.ray = ray
        self.workers = workers
        self.started = False
        if not ray.is_initialized():
            kwargs = dict(
                include_dashboard=False, log_to_driver=False, ignore_reinit_error=True, configure_logging=False
            )
            try:
                if address:
                    ray.init(address=address, **kwargs)
                else:
                    ray.init(num_cpus=workers, **kwargs)
            except Exception as exc:  # cannot reach the cluster, bad address ...
                raise CharctlError(
                    f"cannot start Ray (runtime.address={address!r}): {str(exc).splitlines()[0][:160]}"
                ) from None
            self.started = True
        self.remote = ray.remote(num_cpus=1)(_eval_chunk)
        self.settings_ref = ray.put(settings)

    def __call__(self, genomes: np.ndarray) -> dict[str, np.ndarray]:
        chunks = _split(genomes, self.workers)
        return _merge(self.ray.get([self.remote.remote(self.settings_ref, c) for c in chunks]))

    def close(self) -> None:
        if self.started:
            self.ray.shutdown()


RUNTIMES: dict[str, Callable[..., object]] = {
    "local": LocalEvaluator,
    "process": ProcessEvaluator,
    "ray": RayEvaluator,
}


class make_evaluator:
    """Context manager: `with make_evaluator(cfg.runtime, settings) as evaluate: evaluate(genomes)`."""

    def __init__(self, runtime, settings: Settings) -> None:
        kind = str(runtime.kind)
        if kind not in RUNTIMES:
            raise CharctlError(f"unknown runtime.kind {kind!r}; choose one of: {', '.join(RUNTIMES)}")
        self.evaluator = RUNTIMES[kind](settings, int(runtime.workers), str(runtime.address or ""))

    def __enter__(self):
        return self.evaluator

    def __exit__(self, *exc) -> None:
        self.evaluator.close()
