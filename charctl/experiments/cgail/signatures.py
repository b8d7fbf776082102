"""The named signatures of issue 24's ten-skill target: which motion number must match the clip's for a skill to
count as performed, and whether it does.

A skill's pose coverage alone cannot tell a kick from the guard around it (a standing guard covers 0.45 of the kick
clip's frames), so the target pairs it with a signature the guard misses: the kicks' and the spinkick's foot peak
(m), the jump's airborne share, the spins' yaw rate (rad/s), each within `SIGNATURE_WITHIN` of the clip's. Used by
`scripts/check_targets_cgail.py` (the written targets) and by `charctl eval RUN --checkpoints --rank fidelity` (the
checkpoint selection counts a skill only when both hold). The entries are `fidelity.json`'s per-skill ones
(`fidelity.score_recording`): `clip`, `policy` and `reference` signatures.
"""

from __future__ import annotations

SIGNATURE_WITHIN = 0.3  # |policy - clip| <= this share of |clip| (the ten-skill target)
NAMED = {"kick": ("foot",), "spinkick": ("foot", "yaw_rate"), "jump": ("airborne",), "dance_a": ("yaw_rate",)}


def clip_base(clip: str) -> str:
    """The clip's file name without the ':mirror' suffix of a mirrored skill ('kick:mirror' -> 'kick')."""
    return clip.split(":")[0]


def kicking_foot(sig: dict) -> str:
    """'right' or 'left': the foot that rises higher in the clip's signature `sig` (`fidelity.json` reference)."""
    return "right" if sig["right_foot_peak"] >= sig["left_foot_peak"] else "left"


def within(value: float, reference: float, share: float) -> bool:
    """|value - reference| <= share x |reference|."""
    return abs(value - reference) <= share * abs(reference)


def named_signatures(clip: str) -> tuple[str, ...]:
    """The signature entries the ten-skill target names for a skill of clip `clip` ('foot': the kicking foot's
    peak); none for the other clips (walk, run, punches, breakdance)."""
    return NAMED.get(clip_base(clip), ())


def signature_value(sig: dict, name: str, foot: str) -> float:
    """Entry `name` of signature `sig` ('foot': the `foot` ('right'/'left') foot's peak height, m)."""
    return sig[f"{foot}_foot_peak"] if name == "foot" else sig[name]


def signature_checks(entry: dict, share: float = SIGNATURE_WITHIN) -> list[tuple[str, float, float, bool]]:
    """One (label, policy value, clip value, within `share`) per named signature of one skill's fidelity entry
    (label: 'right foot peak' / 'left foot peak' for the kicking foot, else the entry's name in words)."""
    foot = kicking_foot(entry["reference"])
    checks = []
    for name in named_signatures(entry["clip"]):
        p, r = (signature_value(entry[side], name, foot) for side in ("policy", "reference"))
        label = f"{foot} foot peak" if name == "foot" else name.replace("_", " ")
        checks.append((label, p, r, within(p, r, share)))
    return checks


def signatures_met(entry: dict, share: float = SIGNATURE_WITHIN) -> bool:
    """Whether every named signature of one skill's fidelity entry is within `share` of its clip's (True for a
    skill with none)."""
    return all(ok for *_, ok in signature_checks(entry, share))
