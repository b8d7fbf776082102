"""What a finished (or interrupted) run writes: best genome JSON, gait numbers, the limp test,
the figures; shared by `train`, `eval --curves`, `export` and the repro report."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from charctl.errors import CharctlError
from charctl.experiments.hopper_ga.model import evaluate_genomes
from charctl.experiments.hopper_ga.settings import Settings, describe_invalid

NAME = "hopper-ga"


def gait_summary(genome: np.ndarray, s: Settings) -> dict:
    """eval, gamma, E_r, E and the gait numbers of one genome (one cycle = one step)."""
    m = {k: v[0] for k, v in evaluate_genomes(np.asarray(genome, dtype=float)[None], s).items()}
    if not m["valid"]:
        raise CharctlError(f"the genome is physically impossible: {describe_invalid(int(m['code']))}")
    cycle = float(m["stance_time"] + m["flight_time"])
    return {
        "eval": float(m["fitness"]),
        "gamma": float(m["gamma"]),
        "E_r": float(m["E_r"]),
        "E": float(m["E"]),
        "stance_time_s": float(m["stance_time"]),
        "flight_time_s": float(m["flight_time"]),
        "cycle_time_s": cycle,
        "step_length_m": float(m["step_length"]),
        "stride_length_m": 2.0 * float(m["step_length"]),  # right + left step
        "cadence_spm": 60.0 / cycle,  # steps per minute
    }


def genome_dict(genome: np.ndarray, s: Settings) -> dict[str, float]:
    return {n: float(v) for n, v in zip(s.gene_names, genome)}


def limp_test(genome: np.ndarray, s: Settings, cycles: int, factor: float):
    """Normal run vs a run whose left-leg cycles go `factor` times faster (paper Fig 3.13)."""
    from charctl.experiments.hopper_ga.motion import run_motion

    normal = run_motion(genome, s, cycles)
    try:
        limping = run_motion(genome, s, cycles, limp_factor=factor)
    except CharctlError as exc:  # the faster limp cycle may be physically impossible for this genome
        return normal, None, {"speed_factor": factor, "error": str(exc), **_tracking(normal)}

    def stance(m, leg: int) -> float:
        """Mean stance duration (s) of one leg: its support time / its number of stances."""
        on = m.support == leg
        dt = m.rollout.timeline.dt[0]
        starts = int(np.sum(on[1:] & ~on[:-1])) + int(on[0])
        return float(np.sum(dt[1:][on[1:]]) / max(starts, 1))

    numbers = {
        "speed_factor": factor,
        "normal_mean_com_z_m": float(np.mean(normal.com[:, 2])),
        "limp_mean_com_z_m": float(np.mean(limping.com[:, 2])),
        "normal_stance_right_s": stance(normal, 0),
        "normal_stance_left_s": stance(normal, 1),
        "limp_stance_right_s": stance(limping, 0),
        "limp_stance_left_s": stance(limping, 1),
        **_tracking(normal),
    }
    return normal, limping, numbers


def _tracking(m) -> dict:
    """RMS distance (m) between the actual and the target COM in the ground plane, and whether the
    balance joints stayed inside balance.angle_limit over the whole run."""
    return {
        "com_tracking_rms_m": float(np.sqrt(np.mean(np.sum((m.com[:, [0, 2]] - m.target) ** 2, 1)))),
        "balance_within_limits": bool(m.rollout.code[0] == 0),
    }


def write_outputs(out: Path, history: dict, genome: np.ndarray, s: Settings, cfg, figures: bool = True) -> dict:
    """best_genome.json, figures (fitness curve, COM path, limp, strip) and the numbers."""
    from charctl.eval.report import write_json
    from charctl.experiments.hopper_ga import plots
    from charctl.experiments.hopper_ga.motion import run_motion

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    gait = gait_summary(genome, s)
    label = f"speed {s.speed:g} m/s, beta {s.beta:g}"
    doc = {
        "speed": s.speed,
        "beta": s.beta,
        "generations": len(history["best"]) - 1,
        **gait,
        "genes": genome_dict(genome, s),
    }
    write_json(out / "best_genome.json", doc)
    normal, limping, limp_numbers = limp_test(genome, s, int(cfg.limp.cycles), float(cfg.limp.speed_factor))
    if figures:
        plots.fitness_curve(history, out / "fitness_curve.png", label)
        plots.com_path(normal, out / "com_path.png", f"{label}: target vs actual COM")
        if limping is not None:
            plots.limp(
                normal,
                limping,
                out / "limp.png",
                f"{label}: left leg limps (HIP speed x{cfg.limp.speed_factor:g} on its stance)",
            )
        plots.strip(run_motion(genome, s, 2), s, genome[0], out / "strip.png", f"{label}: two steps")
    return {"gait": gait, "limp": limp_numbers}


def load_best(run_dir: Path) -> tuple[np.ndarray, dict]:
    """The best genome of a run (best_genome.json, else the checkpoint's hall of fame)."""
    path = Path(run_dir) / "best_genome.json"
    if path.is_file():
        doc = json.loads(path.read_text())
        return np.array(list(doc["genes"].values()), dtype=float), doc
    ckpt = Path(run_dir) / "checkpoints" / "last.pt"
    if ckpt.is_file():
        from charctl.checkpoints import load_checkpoint

        state = load_checkpoint(ckpt, "hopper-ga")
        return state["best_genome"].numpy().astype(float), {}
    raise CharctlError(f"{run_dir} has no best_genome.json or checkpoint; train first: charctl train hopper-ga")


def open_hopper_run(run_dir: Path, overrides: list[str] | None = None):
    """(the re-opened run, its model Settings); a one-line error for a run of another experiment."""
    from charctl.experiments.hopper_ga.config import Config
    from charctl.experiments.hopper_ga.settings import settings_from_config
    from charctl.runs import open_run

    run = open_run(run_dir, Config, overrides or [])
    if run.experiment != NAME:
        raise CharctlError(f"{run_dir} is a {run.experiment!r} run, not hopper-ga")
    return run, settings_from_config(run.cfg)


def run_dirs(targets: list[str], overrides: list[str] | tuple[str, ...] = ()) -> list[Path]:
    """Run directories from targets: a run, a folder of runs, or the experiment name (its latest run)."""
    from charctl.experiments import latest_run_dir

    dirs: list[Path] = []
    for t in targets:
        if t == NAME:
            dirs.append(latest_run_dir(NAME, overrides))
            continue
        p = Path(t)
        runs = sorted(q.parent for q in p.glob("*/config.yaml")) if not (p / "config.yaml").is_file() else [p]
        if not runs:
            raise CharctlError(f"{t} is not a hopper-ga run directory (nor a folder of runs)")
        dirs += runs
    return dirs
