"""Copy a finished cgail run into pretrained/<name>/ as a small, loadable run directory.

    .venv/bin/python scripts/package_pretrained.py RUN_DIR pretrained/<name> [--max-points 500]

Keeps config.yaml, metrics.json, resumes.txt, the TensorBoard scalars and checkpoints/last.pt without the
discriminator's replay buffer (tens of MB of policy samples that only a resumed training run
would use; a resume from the packaged checkpoint starts with an empty buffer). Everything else
in the checkpoint (networks, optimisers, normalisers, counters, RNG states) is kept, so
`charctl eval` and `charctl export` take the packaged directory like any run directory.
`--inference-only` also leaves out the PPO and discriminator optimiser states (Adam's moments, two
thirds of a cgail checkpoint): evaluation and export never read them, and a resume (fine-tuning a
shipped policy) starts those optimisers fresh, saying so. Runs meant to be continued as they were
(pretrained/in-progress/) keep them; `--bf16-moments` stores those moments in bfloat16 (a third of the
checkpoint saved; torch's `Optimizer.load_state_dict` casts them back to float32 on resume, so the
continued run starts from moments rounded to 8 significant bits, not bit-identical ones).

The scalars are rewritten into one event file, each tag thinned to at most `--max-points` evenly
spaced points (first and last kept, step and wall time unchanged; 0 = copy the event files as they
are): a long run logs every iteration and its events would be most of the folder.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np


def thinned_indices(n: int, max_points: int) -> np.ndarray:
    """Indices of at most `max_points` evenly spaced points of n, the first and the last included."""
    if n <= max_points:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, max_points).round().astype(int))


def write_thinned_scalars(src: Path, dest: Path, max_points: int, max_step: int | None = None) -> None:
    """Every scalar tag of the event files under `src` (steps <= `max_step` when given), thinned to
    `max_points` per tag (0 = all), into one event file under `dest`."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from torch.utils.tensorboard import SummaryWriter

    acc = EventAccumulator(str(src), size_guidance={"scalars": 0})
    acc.Reload()
    writer = SummaryWriter(str(dest))
    for tag in acc.Tags().get("scalars", []):
        events = [e for e in acc.Scalars(tag) if max_step is None or e.step <= max_step]
        keep = thinned_indices(len(events), max_points) if max_points > 0 else range(len(events))
        for i in keep:
            e = events[i]
            writer.add_scalar(tag, e.value, e.step, walltime=e.wall_time)
    writer.close()


def drop_optimizer_states(state: dict) -> None:
    """Remove a cgail checkpoint state's optimiser states (PPO's and the discriminator's), in place, and
    mark it `inference_only` (`agent.load_agent_state` then keeps freshly built optimisers)."""
    state.get("ppo", {}).pop("optimizer", None)
    state.pop("disc_opt", None)
    state["inference_only"] = True


def bf16_optimizer_moments(state: dict) -> int:
    """Cast the floating-point per-parameter tensors of a cgail checkpoint state's optimiser states (Adam's
    exp_avg and exp_avg_sq; not `step`) to bfloat16, in place; returns how many tensors were cast."""
    import torch

    cast = 0
    for opt in (state.get("ppo", {}).get("optimizer"), state.get("disc_opt")):
        for per_param in (opt or {}).get("state", {}).values():
            for key, value in per_param.items():
                if key != "step" and torch.is_tensor(value) and value.is_floating_point():
                    per_param[key] = value.to(torch.bfloat16)
                    cast += 1
    return cast


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("dest", type=Path)
    ap.add_argument("--max-points", type=int, default=500, help="points kept per scalar tag (0 = all, files copied)")
    ap.add_argument(
        "--checkpoint",
        default="last.pt",
        help="file in RUN/checkpoints/ to ship as last.pt (e.g. a kept samples_<n>.pt); the scalars are cut at its "
        "sample count and metrics.json records which one it was",
    )
    ap.add_argument(
        "--inference-only",
        action="store_true",
        help="leave out the optimiser states too (a resume then starts them fresh)",
    )
    ap.add_argument(
        "--bf16-moments",
        action="store_true",
        help="store the optimiser moments in bfloat16 (a resumable package a third smaller; resumes from rounded "
        "moments)",
    )
    a = ap.parse_args()
    if a.inference_only and a.bf16_moments:
        raise SystemExit("error: --bf16-moments keeps the optimiser states that --inference-only leaves out; pass one")
    import json

    import torch

    from charctl.checkpoints import checkpoint_file_name
    from charctl.errors import CharctlError
    from charctl.runs import run_experiment

    experiment = run_experiment(a.run_dir)
    try:
        source = a.run_dir / "checkpoints" / checkpoint_file_name(a.checkpoint)
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    if not source.is_file():
        raise SystemExit(f"error: checkpoint not found: {source}")
    payload = torch.load(source, map_location="cpu", weights_only=True)
    payload["state"].pop("replay", None)
    if a.inference_only:
        drop_optimizer_states(payload["state"])
    if a.bf16_moments and bf16_optimizer_moments(payload["state"]) == 0:
        raise SystemExit(f"error: {source} holds no optimiser moments to store in bfloat16")
    chosen = source.name != "last.pt"
    a.dest.mkdir(parents=True, exist_ok=True)
    # an interrupted run has no metrics.json; resumes.txt: a resumed run's override history (charctl/runs.py)
    for name in ("config.yaml", "metrics.json", "resumes.txt"):
        if (a.run_dir / name).is_file():
            shutil.copy2(a.run_dir / name, a.dest / name)
    if chosen:
        metrics_path = a.dest / "metrics.json"
        metrics = json.loads(metrics_path.read_text()) if metrics_path.is_file() else {}
        metrics["packaged_checkpoint"] = {
            "file": source.name,
            "samples": int(payload["state"]["samples"]),
            "iteration": int(payload["state"]["iteration"]),
            "note": "the other entries describe the end of the run; the shipped checkpoint is this earlier one",
        }
        metrics_path.write_text(json.dumps(metrics, indent=2))
    if (a.dest / "tb").exists():
        shutil.rmtree(a.dest / "tb")
    if a.max_points > 0 or chosen:
        max_step = int(payload["state"]["samples"]) if chosen else None
        write_thinned_scalars(a.run_dir / "tb", a.dest / "tb", a.max_points, max_step)
    else:
        shutil.copytree(a.run_dir / "tb", a.dest / "tb")
    (a.dest / "checkpoints").mkdir(exist_ok=True)
    torch.save(payload, a.dest / "checkpoints" / "last.pt")
    size = sum(p.stat().st_size for p in a.dest.rglob("*") if p.is_file())
    print(f"{experiment} run {a.run_dir} -> {a.dest} ({size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
