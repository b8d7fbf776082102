"""Connecting to Ray: a cluster at `--address`, or a local instance sized to this machine.

Starting and sizing a cluster is Ray's job (`ray start --head`, `ray up`; Ray's "Ray Clusters"
documentation); charctl only connects. Ray's own console output is kept quiet (no dashboard, the
workers' logs not forwarded, Ray's logger at ERROR) so the driver's table is what the user sees.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator
from typing import Any

from charctl.errors import CharctlError

RAY_HINT = "pip install 'ray[tune]>=2.40' (or `pip install charctl[ray]`)"


def import_ray(feature: str = "--launcher ray") -> Any:
    """The `ray` module, or a one-line error saying how to install it."""
    try:
        import ray
    except ImportError:
        raise CharctlError(f"{feature} needs Ray: {RAY_HINT}") from None
    return ray


def import_tune() -> Any:
    """The `ray.tune` module (it needs Ray's `tune` extra: pandas, pyarrow ...)."""
    import_ray("charctl tune")
    try:
        from ray import tune
    except ImportError as exc:
        raise CharctlError(f"charctl tune needs Ray Tune ({exc}): {RAY_HINT}") from None
    return tune


@contextlib.contextmanager
def ray_session(address: str | None, feature: str = "--launcher ray") -> Iterator[Any]:
    """Ray, initialised for the duration: an already initialised session is reused as it is; else
    connect to `address` ("auto", "HOST:PORT", "ray://HOST:10001"), or with no address (and no
    RAY_ADDRESS in the environment) start a local instance using every CPU and GPU of this
    machine. Whatever this call started it shuts down."""
    ray = import_ray(feature)
    if ray.is_initialized():
        yield ray
        return
    os.environ.setdefault("RAY_DEDUP_LOGS", "0")
    kwargs = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    try:
        ray.init(address=address or None, **kwargs)
    except Exception as exc:  # unreachable cluster, bad address, no permission on /tmp/ray ...
        where = f"the Ray cluster at {address!r}" if address else "a local Ray instance"
        raise CharctlError(f"cannot connect to {where}: {_first_line(exc)}") from None
    try:
        yield ray
    finally:
        with contextlib.suppress(Exception):
            ray.shutdown()


def cluster_summary(ray: Any) -> str:
    """'2 CPUs, 0 GPUs on 1 node(s)'."""
    res = ray.cluster_resources()
    nodes = sum(1 for k in res if k.startswith("node:") and k != "node:__internal_head__")
    return f"{res.get('CPU', 0):g} CPUs, {res.get('GPU', 0):g} GPUs on {nodes} node(s)"


def _first_line(exc: BaseException) -> str:
    lines = [line for line in str(exc).strip().splitlines() if line.strip()]
    return (lines[0] if lines else type(exc).__name__)[:200]
