"""The paper's Table 1 feature settings (19 cases) and how a config selects one (`case=`).

The paper gives the cases in words (its Table 1 numbers are not in the text we have):
  1-7    future positions only, n = 1..7 samples every 20 frames
  8-9    the same 100-frame horizon as 4 x 25 and 3 x 33
  10-11  + past trajectory (here: 2 past samples at the future spacing) on 5 x 20 and 4 x 25
  12-15  4 x 25, position + velocity with weights 1:0, 0.8:0.2, 0.6:0.4, 0.5:0.5
  16-19  4 x 25, position:velocity 0.8:0.2, discount gamma = 0.9, 0.8, 0.7, 0.6
Every case sets all the trajectory keys, so it does not depend on the features.* defaults
(the pose blocks and the runtime are shared by all cases).
"""

from __future__ import annotations

import json
from pathlib import Path

from charctl.errors import CharctlError


def _case(n: int, spacing: int, past: int = 0, pos: float = 1.0, vel: float = 0.0, gamma: float = 1.0) -> dict:
    return {
        "future_samples": n,
        "future_spacing": spacing,
        "past_samples": past,
        "past_spacing": spacing,
        "position_weight": pos,
        "velocity_weight": vel,
        "direction_weight": 0.0,
        "discount": gamma,
    }


TABLE1: dict[int, dict] = {
    **{n: _case(n, 20) for n in range(1, 8)},
    8: _case(4, 25),
    9: _case(3, 33),
    10: _case(5, 20, past=2),
    11: _case(4, 25, past=2),
    12: _case(4, 25, pos=1.0, vel=0.0),
    13: _case(4, 25, pos=0.8, vel=0.2),
    14: _case(4, 25, pos=0.6, vel=0.4),
    15: _case(4, 25, pos=0.5, vel=0.5),
    **{16 + k: _case(4, 25, pos=0.8, vel=0.2, gamma=g) for k, g in enumerate((0.9, 0.8, 0.7, 0.6))},
}


def describe(case: int) -> str:
    """Short text of a Table 1 case, e.g. '4x25 pos:vel 0.8:0.2 γ0.7'."""
    c = TABLE1[case]
    text = f"{c['future_samples']}x{c['future_spacing']}"
    if c["past_samples"]:
        text += f" +past {c['past_samples']}x{c['past_spacing']}"
    if c["velocity_weight"] > 0 or case in (12, 13, 14, 15):
        text += f" pos:vel {c['position_weight']:g}:{c['velocity_weight']:g}"
    if c["discount"] < 1:
        text += f" γ{c['discount']:g}"
    return text


def with_case(cfg, case: int):
    """A copy of cfg with the trajectory feature keys of Table 1 case `case`."""
    from omegaconf import OmegaConf

    if case not in TABLE1:
        raise CharctlError(f"case must be 1..19 (Table 1), got {case}")
    out = OmegaConf.create(OmegaConf.to_container(cfg, resolve=True))
    for k, v in TABLE1[case].items():
        out.features[k] = v
    out.case = str(case)
    return out


def resolve_case(cfg):
    """Apply `cfg.case` ("" | "1".."19" | "best"); returns (cfg, case number or None)."""
    spec = str(cfg.case).strip()
    if not spec:
        return cfg, None
    if spec == "best":
        case = best_case_from_sweeps(cfg.output_root)
    else:
        try:
            case = int(spec)
        except ValueError:
            raise CharctlError(f"case must be empty, 1..19 or 'best', got {spec!r}") from None
    return with_case(cfg, case), case


def best_case_from_sweeps(output_root: str) -> int:
    """The best case recorded by the most recent sweep (sweep.json under output_root)."""
    found = sorted(Path(output_root).glob("**/sweep.json"), key=lambda p: p.stat().st_mtime)
    if not found:
        raise CharctlError(
            f"case=best: no sweep results (sweep.json) under {output_root}/ — "
            "run `charctl eval motion-matching --sweep` first"
        )
    data = json.loads(found[-1].read_text())
    return int(data["best_case"])
