"""PPO hyper-parameters (no torch import: configs load fast)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Literal

from charctl.config_fields import check_fields, ranged


@dataclass
class PPOConfig:
    """PPO hyper-parameters (defaults: a common PPO setting; experiments set their paper's values)."""

    lr: float = ranged(3e-4, gt=0)  # Adam learning rate of actor and critic
    gamma: float = ranged(0.99, ge=0, lt=1)  # discount
    lam: float = ranged(0.95, ge=0, le=1)  # GAE lambda
    clip: float = ranged(0.2, gt=0)  # surrogate clip range epsilon
    epochs: int = ranged(5, ge=1)  # passes over each rollout
    minibatch_size: int = ranged(512, ge=1)  # samples per gradient step
    value_coef: float = ranged(0.5, ge=0)  # weight of the value loss
    entropy_coef: float = ranged(0.0, ge=0)  # weight of the entropy bonus (0 with a fixed std)
    max_grad_norm: float = ranged(1.0, gt=0)  # global gradient-norm clip
    normalize_advantages: bool = True  # per-minibatch advantage standardisation
    value_clip: float = ranged(0.0, ge=0)  # >0: PPO2-style value clipping range
    hidden: list[int] = ranged(factory=lambda: [256, 256], ge=1)  # MLP widths of actor and critic
    # hidden-layer nonlinearity (charctl.nn.mlp.ACTIVATIONS)
    activation: Annotated[str, Literal["relu", "tanh", "elu", "silu"]] = "relu"
    action_std: float = ranged(0.1, gt=0)  # initial std of the Gaussian policy (in action units)
    learn_std: bool = False  # keep the std fixed (paper) or learn it
    # Precision of the update's hidden layers: fp32, bf16 (autocast; output layers, losses and the Adam
    # state stay fp32, and the old log-probs are recomputed in the same precision so the ratio starts at
    # exactly 1) or auto (bf16 where the hardware multiplies bf16 natively: a CPU with AMX-BF16 or
    # AVX512-BF16, a CUDA GPU with bf16; else fp32). bf16 made a PPO minibatch step 2.2x faster on this
    # project's Sapphire Rapids core pair; without native support it is slower. docs/cgail.md, "Throughput".
    update_precision: Annotated[str, Literal["fp32", "bf16", "auto"]] = "fp32"
    # KL-targeting learning rate (rsl_rl's "adaptive" schedule): > 0 measures, before each minibatch step,
    # the mean KL(pi_old || pi_now) of the minibatch (nats, exact for the diagonal Gaussian) and divides
    # the Adam learning rate by 1.5 when it exceeds 2 x desired_kl, multiplies it by 1.5 when it is below
    # desired_kl / 2, within [lr_min, lr_max]. 0 keeps `lr` fixed. The rate is logged as train/ppo_lr and
    # saved in the checkpoint's optimiser state, so a resume continues from it.
    desired_kl: float = 0.0
    lr_min: float = 1e-6  # lower bound of the adaptive learning rate
    lr_max: float = 1e-3  # upper bound of the adaptive learning rate
    # Weight of the symmetry (mirror) loss (charctl.rl.symmetry; Yu et al. 2018, rsl_rl's mirror_loss_coeff):
    # the mean squared difference (action units^2) between the action mean on mirrored states and the mirror of
    # the action mean, added to each minibatch's loss, on the samples whose experiment defines a mirror (cgail:
    # commands whose clips are each other's mirror, e.g. right_kick = kick and left_kick = kick:mirror), so
    # what one side of a pair learns the other gets. 0: off; only experiments that build a mirror accept > 0.
    mirror_loss: float = ranged(0.0, ge=0)


def check_ppo(ppo) -> str | None:
    """A PPO section's declared choices (charctl.config_fields.check_fields, so a PPOConfig made in code is
    checked too; validate checks the declared ranges) and its cross-field rules; a one-line message or None."""
    if (msg := check_fields(ppo, PPOConfig, "ppo.", ranges=False)) is not None:
        return msg
    if ppo.desired_kl < 0:
        return f"ppo.desired_kl must be >= 0 (0 keeps the learning rate fixed), got {ppo.desired_kl}"
    if ppo.desired_kl > 0 and not 0 < ppo.lr_min <= ppo.lr_max:
        return f"ppo.lr_min and ppo.lr_max must satisfy 0 < lr_min <= lr_max, got {ppo.lr_min} and {ppo.lr_max}"
    return None
