"""How far is a cgail policy from mirror symmetry on its mirrored skill pairs (the kicks, the punches)?

    .venv/bin/python scripts/diag_mirror.py RUN [--envs 8] [--steps 60] [--checkpoint samples_N.pt]

For every skill whose clip has its mirror among the run's skills (right_kick = kick, left_kick = kick:mirror), the
policy is rolled out from the clip's frame 0 (evaluation rules, mean actions, the skill held) and, on the states it
visits, the mirror loss of ppo.mirror_loss is measured (`charctl.rl.symmetry.mirror_loss`: mean squared difference,
action units^2, between the action mean on the mirrored state and partner command and the mirror of the action
mean), beside the mean squared action for scale. 0 is a symmetric policy. Works on any run, trained with the mirror
loss or not (docs/cgail.md, "A mirror loss for the mirrored pairs").
"""

from __future__ import annotations

import argparse

import torch

from charctl.errors import CharctlError


def measure(run, skill: int, envs: int, steps: int) -> tuple[float, float]:
    """(mirror loss, mean squared action) on the states of `envs` rollouts of `steps` control steps of `skill`."""
    from charctl.experiments.cgail.symmetry import policy_mirror
    from charctl.rl.symmetry import mirror_loss

    cfg, model = run.cfg, run.agent.model
    m = policy_mirror(cfg, run.agent.skills).to("cpu")
    env = run.held_env([skill] * envs, steps / cfg.env.control_hz + 1.0, seed=0)
    states, commands = [], []
    for _ in range(steps):
        states.append(torch.as_tensor(env.state, dtype=torch.float32))
        commands.append(torch.as_tensor(env.command_blend(), dtype=torch.float32))
        env.step(run.mean_action(env))
    s, c = torch.cat(states), torch.cat(commands)
    with torch.no_grad():
        mean = model.mean_action(s, c)
        loss = mirror_loss(model.mean_action(m.obs(s), m.cond(c)), mean, m)
    return float(loss), float(mean.square().mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("--envs", type=int, default=8)
    ap.add_argument("--steps", type=int, default=60, help="control steps per rollout (30 Hz)")
    ap.add_argument("--checkpoint", default=None, help="a file in RUN/checkpoints/ instead of last.pt")
    args = ap.parse_args()
    if min(args.envs, args.steps) < 1:
        raise SystemExit("error: --envs and --steps must be >= 1")
    from charctl.experiments.cgail.policy import load_trained_run
    from charctl.experiments.cgail.symmetry import command_mirror

    try:
        run = load_trained_run(args.run, args.checkpoint)
        _, paired = command_mirror([s.clip_name for s in run.agent.skills])
        if not paired.any():
            raise CharctlError(f"{args.run} has no skills whose clips mirror each other")
        rows = [(k, *measure(run, k, args.envs, args.steps)) for k in range(len(paired)) if paired[k]]
    except CharctlError as exc:
        raise SystemExit(f"error: {exc}") from None
    print(f"{args.run}: {args.envs} envs x {args.steps} steps from each clip's frame 0")
    print(f"{'skill':14s} {'mirror loss':>12s} {'mean a^2':>10s}")
    for k, loss, scale in rows:
        print(f"{run.skill_names[k]:14s} {loss:12.4f} {scale:10.3f}")


if __name__ == "__main__":
    main()
