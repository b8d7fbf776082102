"""Proximal policy optimisation (clipped surrogate) with a Gaussian actor-critic.

One readable file: `PPOConfig` (hyper-parameters, with help text), `ActorCritic` (MLP mean and
value conditioned on an optional command vector, observation normalisation built in, fixed or
learned diagonal std), `ppo_losses` (the maths, testable on its own) and `PPO` (minibatch epochs,
gradient clipping, state dict for checkpoints). Used by cgail (ReLU [1024, 512, 512]) and srb
(tanh 4 x 64).
"""

from __future__ import annotations

import math

import torch
from torch import nn

from charctl.nn.mlp import RunningNorm, mlp
from charctl.rl.config import PPOConfig
from charctl.rl.storage import RolloutStorage
from charctl.rl.symmetry import Mirror, mirror_loss


class ActorCritic(nn.Module):
    """pi(a | s, c) = N(mu(norm(s), c), diag(std^2)) and V(norm(s), c)."""

    def __init__(self, obs_dim: int, act_dim: int, cfg: PPOConfig, cond_dim: int = 0):
        super().__init__()
        self.obs_dim, self.act_dim, self.cond_dim = obs_dim, act_dim, cond_dim
        self.obs_norm = RunningNorm(obs_dim)
        self.actor = mlp(obs_dim + cond_dim, cfg.hidden, act_dim, cfg.activation, out_gain=0.01)
        self.critic = mlp(obs_dim + cond_dim, cfg.hidden, 1, cfg.activation)
        self.log_std = nn.Parameter(torch.full((act_dim,), math.log(cfg.action_std)), requires_grad=cfg.learn_std)

    def _input(self, obs: torch.Tensor, cond: torch.Tensor | None) -> torch.Tensor:
        x = self.obs_norm(obs)
        return x if self.cond_dim == 0 or cond is None else torch.cat([x, cond], dim=-1)

    def network_input(self, obs: torch.Tensor, cond: torch.Tensor | None = None) -> torch.Tensor:
        """Normalised observation with the command appended: the input of both heads (no parameters)."""
        with torch.no_grad():
            return self._input(obs, cond)

    def mean_action(self, obs: torch.Tensor, cond: torch.Tensor | None = None) -> torch.Tensor:
        return self.actor(self._input(obs, cond))

    def value(self, obs: torch.Tensor, cond: torch.Tensor | None = None) -> torch.Tensor:
        return self.critic(self._input(obs, cond)).squeeze(-1)

    @torch.no_grad()
    def act(self, obs: torch.Tensor, cond: torch.Tensor | None = None, deterministic: bool = False):
        """One batched forward: (actions, log_probs, values)."""
        x = self._input(obs, cond)
        mean = self.actor(x)
        value = self.critic(x).squeeze(-1)
        std = self.log_std.exp().expand_as(mean)
        action = mean if deterministic else mean + std * torch.randn_like(mean)
        return action, gaussian_log_prob(action, mean, self.log_std), value

    def heads(self, x: torch.Tensor, low_precision: torch.dtype | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """(action mean, value) of network inputs `x`; with `low_precision` the hidden layers run under
        autocast in that dtype and the two output layers in fp32."""
        return self.action_mean(x, low_precision), _in_precision(self.critic, x, low_precision).squeeze(-1)

    def action_mean(self, x: torch.Tensor, low_precision: torch.dtype | None = None) -> torch.Tensor:
        """The action mean of network inputs `x` alone (`heads` without the critic), in the same precision."""
        return _in_precision(self.actor, x, low_precision)


def _in_precision(net: nn.Sequential, x: torch.Tensor, low_precision: torch.dtype | None) -> torch.Tensor:
    """`net(x)`, its hidden layers under autocast in `low_precision` (None: fp32) and its output layer in fp32."""
    if low_precision is None:
        return net(x)
    with torch.autocast(x.device.type, dtype=low_precision):
        h = net[:-1](x)
    return net[-1](h.float())


_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


def gaussian_log_prob(actions: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """log N(actions; mean, diag(exp(log_std)^2)) summed over the last axis (nats).

    Written out (the same value as torch.distributions.Normal(...).log_prob(...).sum(-1)) so the hot
    paths skip the distribution object's argument validation."""
    z = (actions - mean) * torch.exp(-log_std)
    return -(0.5 * z.square() + log_std + _LOG_SQRT_2PI).sum(-1)


def gaussian_entropy(log_std: torch.Tensor) -> torch.Tensor:
    """Entropy (nats) of a diagonal Gaussian with these log standard deviations: sum(0.5 + log sqrt(2 pi) + log std)."""
    return (0.5 + _LOG_SQRT_2PI + log_std).sum(-1)


def gaussian_kl(mean_p: torch.Tensor, log_std_p: torch.Tensor, mean_q: torch.Tensor, log_std_q: torch.Tensor):
    """KL(p || q) (nats) of two diagonal Gaussians, summed over the last axis:
    sum(log sq - log sp + (sp^2 + (mp - mq)^2) / (2 sq^2) - 1/2)."""
    var_ratio = torch.exp(2.0 * (log_std_p - log_std_q))
    mahalanobis = (mean_p - mean_q).square() * torch.exp(-2.0 * log_std_q)
    return (log_std_q - log_std_p + 0.5 * (var_ratio + mahalanobis) - 0.5).sum(-1)


def adapted_lr(lr: float, kl: float, desired_kl: float, lr_min: float, lr_max: float) -> float:
    """The next learning rate of the KL-targeting schedule: /1.5 above 2 x desired_kl, x1.5 below half of
    it, unchanged in between; kept within [lr_min, lr_max]."""
    if kl > 2.0 * desired_kl:
        lr = lr / 1.5
    elif kl < 0.5 * desired_kl:
        lr = lr * 1.5
    return min(max(lr, lr_min), lr_max)


LOG_RATIO_LIMIT = 20.0  # |log pi_new - log pi_old| above this is clamped (exp(20) = 4.9e8, finite in float32)


def behaviour_weights(proximal_logp: torch.Tensor, behaviour_logp: torch.Tensor) -> torch.Tensor:
    """min(1, pi_prox / pi_behav) per sample: the importance weight of the decoupled PPO objective
    (Hilton et al. 2021, "Batch size-invariance for policy optimization") for data collected by an
    older behaviour policy, truncated at 1 as IMPALA's V-trace truncates rho (bounded variance)."""
    return torch.exp(torch.clamp(proximal_logp - behaviour_logp, -LOG_RATIO_LIMIT, 0.0))


def ppo_losses(
    new_logp: torch.Tensor,
    old_logp: torch.Tensor,
    advantages: torch.Tensor,
    values: torch.Tensor,
    old_values: torch.Tensor,
    returns: torch.Tensor,
    clip: float,
    value_clip: float = 0.0,
    weights: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """Clipped surrogate and value losses (to minimise) and diagnostics.

    L_pi = -E[w min(rho A, clip(rho, 1-eps, 1+eps) A)], rho = exp(new_logp - old_logp), w = 1 unless
    `weights` are given (the decoupled objective's behaviour correction, see `behaviour_weights`);
    L_V = E[(V - R)^2] (or the max with the clipped version when value_clip > 0).
    """
    # The log-ratio is clamped before exp: one sample whose log-probability moved by > 88 nats within an
    # update would otherwise make the ratio 0 or inf, the loss or approx_kl inf, and end the run as
    # diverged. Inside +-20 nothing changes; a sample beyond it contributes no gradient.
    log_ratio = new_logp - old_logp
    ratio = torch.exp(torch.clamp(log_ratio, -LOG_RATIO_LIMIT, LOG_RATIO_LIMIT))
    surr = torch.min(ratio * advantages, torch.clamp(ratio, 1.0 - clip, 1.0 + clip) * advantages)
    policy_loss = -(surr if weights is None else weights * surr).mean()
    if value_clip > 0:
        v_clipped = old_values + torch.clamp(values - old_values, -value_clip, value_clip)
        value_loss = torch.max((values - returns) ** 2, (v_clipped - returns) ** 2).mean()
    else:
        value_loss = ((values - returns) ** 2).mean()
    clip_frac = ((ratio - 1.0).abs() > clip).float().mean()
    approx_kl = ((ratio - 1.0) - torch.log(ratio)).mean()
    ratio_clamped = (log_ratio.abs() > LOG_RATIO_LIMIT).float().mean()  # charctl.guard stops above 1 %
    return {
        "policy": policy_loss,
        "value": value_loss,
        "clip_frac": clip_frac,
        "approx_kl": approx_kl,
        "ratio_clamped": ratio_clamped,
    }


def make_adam(params, lr: float) -> torch.optim.Adam:
    """Adam with the fused kernel (one kernel for all parameters; several times faster than the
    per-tensor loop for small MLPs on CPU, same update rule)."""
    return torch.optim.Adam(params, lr=lr, fused=True)


def cpu_has_native_bf16() -> bool:
    """True where the CPU flags (Linux /proc/cpuinfo) list AMX-BF16 or AVX512-BF16; False elsewhere."""
    try:
        text = open("/proc/cpuinfo", encoding="ascii", errors="ignore").read()
    except OSError:
        return False
    flags = set(text.split())
    return bool(flags & {"amx_bf16", "avx512_bf16"})


def resolve_update_precision(choice: str, device: torch.device) -> str:
    """The precision (fp32 | bf16) the update runs in for the config's `choice` on `device`
    (auto: bf16 where the hardware multiplies bf16 natively, else fp32)."""
    if choice != "auto":
        return choice
    if device.type == "cuda":
        return "bf16" if torch.cuda.is_bf16_supported() else "fp32"
    return "bf16" if device.type == "cpu" and cpu_has_native_bf16() else "fp32"


class PPO:
    """Owns the actor-critic and its optimiser; `update(storage)` runs the minibatch epochs."""

    def __init__(
        self,
        model: ActorCritic,
        cfg: PPOConfig,
        generator: torch.Generator | None = None,
        mirror: Mirror | None = None,
    ):
        """`mirror`: the experiment's left/right mirror (`charctl.rl.symmetry`), used when cfg.mirror_loss > 0."""
        self.model, self.cfg = model, cfg
        self.optimizer = make_adam([p for p in model.parameters() if p.requires_grad], lr=cfg.lr)
        self.generator = generator
        device = next(model.parameters()).device
        self.precision = resolve_update_precision(cfg.update_precision, device)
        if cfg.mirror_loss > 0 and mirror is None:
            raise ValueError("ppo.mirror_loss > 0 needs the experiment's mirror (charctl.rl.symmetry.Mirror)")
        self.mirror = mirror.to(device) if mirror is not None and cfg.mirror_loss > 0 else None

    def update(self, storage: RolloutStorage, stale_behaviour: bool = False) -> dict[str, float]:
        """The minibatch epochs on `storage`. `stale_behaviour`: the data was collected by an older policy
        than the current parameters (the overlapped loop's one-iteration lag); the clip is then taken
        around the current (proximal) policy and each sample is weighted by `behaviour_weights` (the
        decoupled objective). Without it, the behaviour policy is the current one and w = 1."""
        cfg = self.cfg
        data = storage.flat()
        n = data["obs"].shape[0]
        mb = min(cfg.minibatch_size, n)
        sums: dict[str, torch.Tensor] = {}  # float64 on the data's device: no host read per minibatch
        steps = 0
        # The observation normaliser is frozen during the update: normalise the whole batch once.
        inputs = self.model.network_input(data["obs"], data["cond"] if self.model.cond_dim else None)
        low = {"fp32": None, "bf16": torch.bfloat16}[self.precision]
        start_policy = self._start_policy(data, inputs, low, stale_behaviour)
        weights = start_policy[3]
        mirrored = self._mirrored_inputs(data)
        for _ in range(cfg.epochs):
            perm = torch.randperm(n, generator=self.generator).to(data["obs"].device)
            for start in range(0, n - mb + 1, mb):
                idx = perm[start : start + mb]
                for k, v in self._minibatch_step(data, inputs, idx, low, *start_policy, mirrored).items():
                    sums[k] = sums.get(k, 0.0) + v.detach().double()
                steps += 1
        stats = {f"losses/{k}": float(v) / max(steps, 1) for k, v in sums.items()}
        stats["train/ppo_lr"] = self.optimizer.param_groups[0]["lr"]
        if weights is not None:
            stats["losses/behaviour_weight"] = float(weights.mean())
        return stats

    def _mirrored_inputs(self, data: dict) -> tuple[torch.Tensor, torch.Tensor] | None:
        """(network inputs of the mirrored states and commands (n, in_dim), (n,) bool the mirror applies), or
        None without a mirror loss; normalised once, like the inputs (the normaliser is frozen here)."""
        if self.mirror is None:
            return None
        m = self.mirror
        return self.model.network_input(m.obs(data["obs"]), m.cond(data["cond"])), m.applies(data["cond"])

    def _start_policy(self, data: dict, inputs: torch.Tensor, low: torch.dtype | None, stale_behaviour: bool) -> tuple:
        """The policy at the update's start, in the update's precision `low` (None: fp32), where it is needed:
        (old_mean, old_log_std, old_logp, weights). old_logp is the storage's behaviour log-probs unless
        recomputed (low precision or stale behaviour, so the ratio starts at exactly 1); weights are the
        decoupled objective's behaviour weights, or None."""
        old_logp = data["log_probs"]
        old_mean = old_log_std = None
        weights = None
        if low is not None or self.cfg.desired_kl > 0 or stale_behaviour:
            with torch.no_grad():
                old_mean, old_log_std = self.model.heads(inputs, low)[0], self.model.log_std.detach().clone()
                if low is not None or stale_behaviour:  # the ratio starts at exactly 1
                    old_logp = gaussian_log_prob(data["actions"], old_mean, old_log_std)
                if stale_behaviour:  # compared with the fp32 behaviour log-probs: the proximal ones in fp32 too
                    prox_mean = old_mean if low is None else self.model.heads(inputs)[0]
                    prox_logp = gaussian_log_prob(data["actions"], prox_mean, old_log_std)
                    weights = behaviour_weights(prox_logp, data["log_probs"])
        return old_mean, old_log_std, old_logp, weights

    def _minibatch_step(
        self,
        data: dict,
        inputs: torch.Tensor,
        idx: torch.Tensor,
        low: torch.dtype | None,
        old_mean: torch.Tensor | None,
        old_log_std: torch.Tensor | None,
        old_logp: torch.Tensor,
        weights: torch.Tensor | None,
        mirrored: tuple[torch.Tensor, torch.Tensor] | None = None,
    ) -> dict[str, torch.Tensor]:
        """One gradient step on the minibatch `idx` (KL-adapting the learning rate first when
        `desired_kl` > 0); returns its losses and the policy entropy. `mirrored`: `_mirrored_inputs`, for the
        mirror loss (weighted by cfg.mirror_loss) on the minibatch's samples where the mirror applies."""
        cfg = self.cfg
        x = inputs[idx]
        adv = data["advantages"][idx]
        if cfg.normalize_advantages and adv.numel() > 1:
            adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        mean, values = self.model.heads(x, low)
        new_logp = gaussian_log_prob(data["actions"][idx], mean, self.model.log_std)
        if cfg.desired_kl > 0:
            self._adapt_lr(old_mean[idx], old_log_std, mean.detach(), self.model.log_std.detach())
        losses = ppo_losses(
            new_logp,
            old_logp[idx],
            adv,
            values,
            data["values"][idx],
            data["returns"][idx],
            cfg.clip,
            cfg.value_clip,
            None if weights is None else weights[idx],
        )
        entropy = gaussian_entropy(self.model.log_std)
        loss = losses["policy"] + cfg.value_coef * losses["value"] - cfg.entropy_coef * entropy
        if mirrored is not None:
            sel = mirrored[1][idx]
            mirrored_mean = self.model.action_mean(mirrored[0][idx][sel], low)
            losses["mirror"] = mirror_loss(mirrored_mean, mean[sel], self.mirror)
            loss = loss + cfg.mirror_loss * losses["mirror"]
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        nn.utils.clip_grad_norm_(self.model.parameters(), cfg.max_grad_norm)
        self.optimizer.step()
        return {**losses, "entropy": entropy}

    def _adapt_lr(self, old_mean, old_log_std, mean, log_std) -> None:
        """One step of the KL-targeting schedule on this minibatch (reads one number to the host)."""
        cfg = self.cfg
        kl = float(gaussian_kl(old_mean, old_log_std, mean, log_std).mean())
        lr = adapted_lr(self.optimizer.param_groups[0]["lr"], kl, cfg.desired_kl, cfg.lr_min, cfg.lr_max)
        for group in self.optimizer.param_groups:
            group["lr"] = lr

    def state_dict(self) -> dict:
        return {"model": self.model.state_dict(), "optimizer": self.optimizer.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
