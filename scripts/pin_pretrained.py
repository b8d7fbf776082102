"""Write RUN/pin.npz for shipped policies (charctl.experiments.cgail.pins): what each computes on fixed
states, checked by tests/test_pretrained_pins.py.

    python scripts/pin_pretrained.py pretrained/cgail-3skill-fidelity [more folders...]
"""

from __future__ import annotations

import sys

from charctl.experiments.cgail.pins import write_pins


def main() -> None:
    if len(sys.argv) < 2:
        sys.exit("usage: pin_pretrained.py RUN [RUN...]")
    for run in sys.argv[1:]:
        print(f"wrote {write_pins(run)}")


if __name__ == "__main__":
    main()
