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
