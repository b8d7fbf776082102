"""PPO hyper-parameters (no torch import: configs load fast)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class PPOConfig:
    """PPO hyper-parameters (defaults: a common PPO setting; experiments set their paper's values)."""

    lr: float = 3e-4  # Adam learning rate of actor and critic
    gamma: float = 0.99  # discount
    lam: float = 0.95  # GAE lambda
    clip: float = 0.2  # surrogate clip range epsilon
    epochs: int = 5  # passes over each rollout
    minibatch_size: int = 512  # samples per gradient step
    value_coef: float = 0.5  # weight of the value loss
    entropy_coef: float = 0.0  # weight of the entropy bonus (0 with a fixed std)
    max_grad_norm: float = 1.0  # global gradient-norm clip
    normalize_advantages: bool = True  # per-minibatch advantage standardisation
    value_clip: float = 0.0  # >0: PPO2-style value clipping range
    hidden: list[int] = field(default_factory=lambda: [256, 256])  # MLP widths of actor and critic
    activation: str = "relu"  # relu | tanh | elu | silu
    action_std: float = 0.1  # initial std of the Gaussian policy (in action units)
    learn_std: bool = False  # keep the std fixed (paper) or learn it
    # Precision of the update's hidden layers: fp32, bf16 (autocast; output layers, losses and the Adam
    # state stay fp32, and the old log-probs are recomputed in the same precision so the ratio starts at
    # exactly 1) or auto (bf16 where the hardware multiplies bf16 natively: a CPU with AMX-BF16 or
    # AVX512-BF16, a CUDA GPU with bf16; else fp32). bf16 made a PPO minibatch step 2.2x faster on this
    # project's Sapphire Rapids core pair; without native support it is slower. docs/cgail.md, "Throughput".
    update_precision: str = "fp32"
    # KL-targeting learning rate (rsl_rl's "adaptive" schedule): > 0 measures, before each minibatch step,
    # the mean KL(pi_old || pi_now) of the minibatch (nats, exact for the diagonal Gaussian) and divides
    # the Adam learning rate by 1.5 when it exceeds 2 x desired_kl, multiplies it by 1.5 when it is below
    # desired_kl / 2, within [lr_min, lr_max]. 0 keeps `lr` fixed. The rate is logged as train/ppo_lr and
    # saved in the checkpoint's optimiser state, so a resume continues from it.
    desired_kl: float = 0.0
    lr_min: float = 1e-6  # lower bound of the adaptive learning rate
    lr_max: float = 1e-3  # upper bound of the adaptive learning rate


UPDATE_PRECISIONS = ("fp32", "bf16", "auto")


def check_ppo(ppo) -> str | None:
    """Choices of a PPO section that the schema's types cannot check; a one-line message or None."""
    if ppo.update_precision not in UPDATE_PRECISIONS:
        return f"ppo.update_precision must be one of {', '.join(UPDATE_PRECISIONS)}, got {ppo.update_precision!r}"
    if ppo.desired_kl < 0:
        return f"ppo.desired_kl must be >= 0 (0 keeps the learning rate fixed), got {ppo.desired_kl}"
    if ppo.desired_kl > 0 and not 0 < ppo.lr_min <= ppo.lr_max:
        return f"ppo.lr_min and ppo.lr_max must satisfy 0 < lr_min <= lr_max, got {ppo.lr_min} and {ppo.lr_max}"
    return None
