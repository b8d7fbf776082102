"""Write RUN/pin.npz for shipped policies (charctl.experiments.cgail.pins): what each computes on fixed
states, checked by tests/test_pretrained_pins.py.

    python scripts/pin_pretrained.py pretrained/cgail-3skill-fidelity [more folders...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from charctl.experiments.cgail.pins import write_pins


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="packaged run folders (each with checkpoints/last.pt)")
    args = parser.parse_args()
    missing = [str(r) for r in args.runs if not (r / "checkpoints" / "last.pt").is_file()]
    if missing:  # every folder checked before any pin is written
        parser.error(f"not a run folder with checkpoints/last.pt: {', '.join(missing)}")
    for run in args.runs:
        print(f"wrote {write_pins(run)}")


if __name__ == "__main__":
    main()
