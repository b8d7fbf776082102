"""Copy a finished cgail run into pretrained/<name>/ as a small, loadable run directory.

    .venv/bin/python scripts/package_pretrained.py RUN_DIR pretrained/<name>

Keeps config.yaml, metrics.json, the TensorBoard events and checkpoints/last.pt without the
discriminator's replay buffer (tens of MB of policy samples that only a resumed training run
would use; a resume from the packaged checkpoint starts with an empty buffer). Everything else
in the checkpoint (networks, optimisers, normalisers, counters, RNG states) is kept, so
`charctl eval` and `charctl export` take the packaged directory like any run directory.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("dest", type=Path)
    a = ap.parse_args()
    import torch

    from charctl.runs import run_experiment

    experiment = run_experiment(a.run_dir)
    payload = torch.load(a.run_dir / "checkpoints" / "last.pt", map_location="cpu", weights_only=True)
    payload["state"].pop("replay", None)
    a.dest.mkdir(parents=True, exist_ok=True)
    for name in ("config.yaml", "metrics.json"):  # an interrupted run has no metrics.json
        if (a.run_dir / name).is_file():
            shutil.copy2(a.run_dir / name, a.dest / name)
    if (a.dest / "tb").exists():
        shutil.rmtree(a.dest / "tb")
    shutil.copytree(a.run_dir / "tb", a.dest / "tb")
    (a.dest / "checkpoints").mkdir(exist_ok=True)
    torch.save(payload, a.dest / "checkpoints" / "last.pt")
    size = sum(p.stat().st_size for p in a.dest.rglob("*") if p.is_file())
    print(f"{experiment} run {a.run_dir} -> {a.dest} ({size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
