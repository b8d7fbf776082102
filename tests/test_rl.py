"""PPO maths: GAE by hand, clipped surrogate, save/load round trip, same seed same weights."""

import math

import pytest
import torch

from charctl.nn.mlp import RunningNorm, mlp
from charctl.rl.ppo import PPO, ActorCritic, PPOConfig, gaussian_entropy, gaussian_log_prob, ppo_losses
from charctl.rl.storage import RolloutStorage, compute_gae


def test_gae_hand_computed():
    # one env, three steps, episode ends after step 1 (index 1)
    r = torch.tensor([[1.0], [2.0], [3.0]])
    v = torch.tensor([[0.5], [1.0], [1.5]])
    d = torch.tensor([[0.0], [1.0], [0.0]])
    last = torch.tensor([2.0])
    g, lam = 0.9, 0.8
    # t=2: delta = 3 + .9*2 - 1.5 = 3.3 ; A2 = 3.3
    # t=1: done -> delta = 2 - 1 = 1.0 ; A1 = 1.0
    # t=0: delta = 1 + .9*1.0 - .5 = 1.4 ; A0 = 1.4 + .9*.8*1.0 = 2.12
    adv, ret = compute_gae(r, v, d, last, g, lam)
    assert adv[:, 0].tolist() == pytest.approx([2.12, 1.0, 3.3])
    assert ret[:, 0].tolist() == pytest.approx([2.62, 2.0, 4.8])


def test_ppo_clipped_loss_values():
    old = torch.zeros(3)
    new = torch.log(torch.tensor([1.5, 0.5, 1.1]))  # ratios 1.5, 0.5, 1.1
    adv = torch.tensor([1.0, 1.0, -2.0])
    v = torch.tensor([1.0, 2.0, 3.0])
    ret = torch.tensor([1.5, 2.0, 2.0])
    out = ppo_losses(new, old, adv, v, v.clone(), ret, clip=0.2)
    # min(r A, clip(r) A): 1.2*1, 0.5*1, min(1.1*-2, 1.1*-2) = -2.2 -> mean = (1.2 + 0.5 - 2.2)/3
    assert float(out["policy"]) == pytest.approx(-(1.2 + 0.5 - 2.2) / 3)
    assert float(out["value"]) == pytest.approx((0.25 + 0 + 1) / 3)
    assert float(out["clip_frac"]) == pytest.approx(2 / 3)


def test_running_norm_matches_batch_statistics():
    torch.manual_seed(0)
    x = torch.randn(1000, 3) * torch.tensor([1.0, 2.0, 3.0]) + 5
    n = RunningNorm(3)
    for chunk in x.split(137):
        n.update(chunk)
    assert torch.allclose(n.mean, x.mean(0), atol=1e-4)
    assert torch.allclose(n.var, x.var(0, unbiased=False), rtol=1e-3)


def _model(seed):
    torch.manual_seed(seed)
    return ActorCritic(4, 2, PPOConfig(hidden=[8, 8], action_std=0.5), cond_dim=3)


def test_same_seed_same_weights_and_state_round_trip(tmp_path):
    a, b = _model(3), _model(3)
    for pa, pb in zip(a.state_dict().values(), b.state_dict().values()):
        assert torch.equal(pa, pb)
    ppo = PPO(a, PPOConfig(hidden=[8, 8]))
    path = tmp_path / "ppo.pt"
    torch.save(ppo.state_dict(), path)
    c = _model(99)
    PPO(c, PPOConfig(hidden=[8, 8])).load_state_dict(torch.load(path, weights_only=True))
    x = torch.randn(5, 4)
    cond = torch.eye(3)[[0, 1, 2, 0, 1]]
    assert torch.allclose(a.mean_action(x, cond), c.mean_action(x, cond))


def test_gaussian_log_prob_and_entropy_by_hand():
    """One 2-D sample by hand: log N = -sum(z^2 / 2 + log s + log sqrt(2 pi)); torch.distributions agrees."""
    a, mu, log_std = torch.tensor([[0.3, -1.0]]), torch.tensor([[0.1, -0.5]]), torch.log(torch.tensor([0.1, 0.5]))
    z2 = (0.2 / 0.1) ** 2 + (0.5 / 0.5) ** 2  # 4 + 1
    hand = -(z2 / 2 + math.log(0.1) + math.log(0.5) + 2 * 0.5 * math.log(2 * math.pi))
    assert gaussian_log_prob(a, mu, log_std).item() == pytest.approx(hand, rel=1e-6)
    ref = torch.distributions.Normal(mu, log_std.exp())
    assert gaussian_log_prob(a, mu, log_std).item() == pytest.approx(ref.log_prob(a).sum().item(), rel=1e-6)
    assert gaussian_entropy(log_std).item() == pytest.approx(ref.entropy().sum().item(), rel=1e-6)


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_ppo_learns_a_contextual_bandit(precision):
    """PPO on a 1-step task: reward = -(a - target(c))^2; the mean action moves to the target,
    with the update in fp32 and with its hidden layers in bf16."""
    torch.manual_seed(0)
    cfg = PPOConfig(hidden=[32, 32], action_std=0.3, lr=3e-3, epochs=4, minibatch_size=64, gamma=0.0, lam=0.0)
    cfg.update_precision = precision
    model = ActorCritic(1, 1, cfg, cond_dim=2)
    ppo = PPO(model, cfg)
    targets = torch.tensor([-1.0, 1.0])
    for _ in range(60):
        st = RolloutStorage(1, 256, 1, 1, 2)
        obs = torch.zeros(256, 1)
        k = torch.randint(0, 2, (256,))
        cond = torch.eye(2)[k]
        a, logp, v = model.act(obs, cond)
        rew = -((a[:, 0] - targets[k]) ** 2)
        st.add(obs, cond, a, logp, v, rew, torch.ones(256))
        st.finish(torch.zeros(256), cfg.gamma, cfg.lam)
        ppo.update(st)
    with torch.no_grad():
        m = model.mean_action(torch.zeros(2, 1), torch.eye(2))[:, 0]
    assert m.tolist() == pytest.approx([-1.0, 1.0], abs=0.15)


def test_mlp_spectral_norm_flag():
    net = mlp(3, [4], 2, spectral_norm=True)
    lins = [m for m in net if isinstance(m, torch.nn.Linear)]
    assert all(hasattr(l, "parametrizations") for l in lins)


def test_ppo_losses_stay_finite_when_the_log_ratio_explodes():
    """A sample whose log-probability moved by 100 nats: ratio clamped to exp(20), losses and KL finite,
    and the other samples' terms unchanged (hand values: ratio exp(0.1), A = 1 -> surrogate 1.1052)."""
    import math

    from charctl.rl.ppo import LOG_RATIO_LIMIT, ppo_losses

    new = torch.tensor([0.1, 100.0, -100.0])
    old = torch.zeros(3)
    adv = torch.tensor([1.0, -1.0, 1.0])
    v = torch.zeros(3)
    out = ppo_losses(new, old, adv, v, v, v, clip=0.2)
    assert all(torch.isfinite(x) for x in out.values())
    big = math.exp(LOG_RATIO_LIMIT)
    # min(rho A, clip(rho) A): 1.1052 -> min(1.1052, 1.2) = 1.1052; -big vs -1.2 -> -big; exp(-20) ~ 0 vs 0.8 -> ~0
    expected = -(math.exp(0.1) - big + math.exp(-LOG_RATIO_LIMIT)) / 3
    assert float(out["policy"]) == pytest.approx(expected, rel=1e-5)


def test_ratio_clamp_share_stops_a_jumping_policy():
    """0.5 % of samples beyond the clamp is an outlier the clamp absorbs; 2 % is divergence (exit 3)."""
    from charctl.errors import Diverged
    from charctl.guard import check_policy_step
    from charctl.rl.ppo import ppo_losses

    new = torch.zeros(200)
    new[:1] = 30.0  # 1 of 200 = 0.5 %
    z = torch.zeros(200)
    share = float(ppo_losses(new, z, z, z, z, z, clip=0.2)["ratio_clamped"])
    assert share == pytest.approx(0.005)
    check_policy_step({"losses/ratio_clamped": share})
    with pytest.raises(Diverged, match="20 nats on 2.0 %"):
        check_policy_step({"losses/ratio_clamped": 0.02}, where="iteration 3")


def test_bf16_update_starts_at_ratio_one_and_bad_precision_is_refused():
    """bf16 recomputes the behaviour log-probs in its own precision: one epoch of lr 0 gives approx_kl = 0
    and no clipping; an unknown precision is a one-line config error."""
    from charctl.rl.config import check_ppo

    torch.manual_seed(1)
    cfg = PPOConfig(hidden=[64, 64], action_std=0.1, lr=0.0, epochs=1, minibatch_size=128)
    cfg.update_precision = "bf16"
    model = ActorCritic(5, 3, cfg)
    st = RolloutStorage(2, 128, 5, 3, 0)
    for _ in range(2):
        obs = 3 * torch.randn(128, 5)
        a, logp, v = model.act(obs)
        st.add(obs, None, a, logp, v, torch.randn(128), torch.zeros(128))
    st.finish(torch.zeros(128), 0.99, 0.95)
    stats = PPO(model, cfg).update(st)
    assert stats["losses/approx_kl"] == pytest.approx(0.0, abs=1e-7)
    assert stats["losses/clip_frac"] == 0.0
    assert check_ppo(cfg) is None
    cfg.update_precision = "fp16"
    assert "ppo.update_precision must be one of fp32, bf16, auto" in check_ppo(cfg)


def test_auto_precision_follows_the_hardware(monkeypatch):
    """auto = bf16 only where bf16 is native (CPU flags amx_bf16/avx512_bf16); explicit choices stay."""
    from charctl.rl import ppo as P

    cpu = torch.device("cpu")
    monkeypatch.setattr(P, "cpu_has_native_bf16", lambda: True)
    assert [P.resolve_update_precision(c, cpu) for c in ("auto", "fp32", "bf16")] == ["bf16", "fp32", "bf16"]
    monkeypatch.setattr(P, "cpu_has_native_bf16", lambda: False)
    assert [P.resolve_update_precision(c, cpu) for c in ("auto", "fp32", "bf16")] == ["fp32", "fp32", "bf16"]


def test_gaussian_kl_matches_torch_and_the_schedule_steps_by_hand():
    """gaussian_kl equals torch.distributions' KL; the schedule divides by 1.5 above 2 x target,
    multiplies by 1.5 below half of it, keeps the rate in between and within its bounds."""
    from charctl.rl.ppo import adapted_lr, gaussian_kl

    torch.manual_seed(3)
    mp, mq = torch.randn(4, 3), torch.randn(4, 3)
    sp, sq = 0.3 * torch.randn(3), 0.3 * torch.randn(3)
    ref = torch.distributions.kl_divergence(
        torch.distributions.Normal(mp, sp.exp()), torch.distributions.Normal(mq, sq.exp())
    ).sum(-1)
    assert torch.allclose(gaussian_kl(mp, sp, mq, sq), ref, rtol=1e-5)
    # equal std: KL = |dm|^2 / (2 s^2); dm = 0.1 in one dim, s = 0.1 -> 0.5 nats
    kl = gaussian_kl(
        torch.tensor([0.1, 0.0]),
        torch.log(torch.tensor([0.1, 0.1])),
        torch.zeros(2),
        torch.log(torch.tensor([0.1, 0.1])),
    )
    assert float(kl) == pytest.approx(0.5, rel=1e-6)
    assert adapted_lr(3e-4, kl=0.05, desired_kl=0.02, lr_min=1e-6, lr_max=1e-3) == pytest.approx(2e-4)
    assert adapted_lr(2e-4, kl=0.005, desired_kl=0.02, lr_min=1e-6, lr_max=1e-3) == pytest.approx(3e-4)
    assert adapted_lr(2e-4, kl=0.02, desired_kl=0.02, lr_min=1e-6, lr_max=1e-3) == 2e-4
    assert adapted_lr(1e-4, kl=0.0, desired_kl=0.02, lr_min=1e-6, lr_max=1e-4) == 1e-4
    assert adapted_lr(1.2e-6, kl=1.0, desired_kl=0.02, lr_min=1e-6, lr_max=1e-4) == 1e-6


def test_adaptive_lr_falls_when_the_update_overshoots_and_is_checked():
    """A large fixed rate moves the policy far past a tiny KL target: the logged rate drops below the
    configured one and never leaves its bounds; a fixed schedule reports the configured rate."""
    from charctl.rl.config import check_ppo

    def run(desired_kl: float) -> dict:
        torch.manual_seed(1)
        cfg = PPOConfig(hidden=[32, 32], action_std=0.1, lr=1e-2, epochs=2, minibatch_size=64, desired_kl=desired_kl)
        cfg.lr_min, cfg.lr_max = 1e-4, 1e-2
        model = ActorCritic(4, 2, cfg)
        st = RolloutStorage(2, 128, 4, 2, 0)
        for _ in range(2):
            obs = torch.randn(128, 4)
            a, logp, v = model.act(obs)
            st.add(obs, None, a, logp, v, torch.randn(128), torch.zeros(128))
        st.finish(torch.zeros(128), 0.99, 0.95)
        return PPO(model, cfg).update(st)

    assert run(0.0)["train/ppo_lr"] == 1e-2
    lr = run(1e-4)["train/ppo_lr"]
    assert 1e-4 <= lr < 1e-2 / 1.5
    cfg = PPOConfig(desired_kl=-1.0)
    assert "ppo.desired_kl must be >= 0" in check_ppo(cfg)
    cfg = PPOConfig(desired_kl=0.01, lr_min=1e-3, lr_max=1e-4)
    assert "0 < lr_min <= lr_max" in check_ppo(cfg)


def test_decoupled_objective_weights_by_hand():
    """behaviour_weights = min(1, pi_prox / pi_behav); the policy loss is the weighted clipped surrogate.
    Hand values: prox - behav = -0.5 -> exp(-0.5) = 0.6065; +0.3 -> 1 (truncated); -100 -> exp(-20)."""
    from charctl.rl.ppo import LOG_RATIO_LIMIT, behaviour_weights

    w = behaviour_weights(torch.tensor([-0.5, 0.3, -100.0]), torch.zeros(3))
    assert w.tolist() == pytest.approx([math.exp(-0.5), 1.0, math.exp(-LOG_RATIO_LIMIT)], rel=1e-6)
    new, old = torch.tensor([0.1, 0.0]), torch.zeros(2)
    adv, v = torch.tensor([1.0, 2.0]), torch.zeros(2)
    out = ppo_losses(new, old, adv, v, v, v, clip=0.2, weights=torch.tensor([0.5, 1.0]))
    assert float(out["policy"]) == pytest.approx(-(0.5 * math.exp(0.1) * 1.0 + 1.0 * 2.0) / 2, rel=1e-6)


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_stale_behaviour_update_clips_around_the_current_policy(precision):
    """Data from an older policy: with lr 0 the update's ratio starts at exactly 1 (no clipping, KL 0)
    although the stored behaviour log-probs differ, and the mean weight is min(1, pi_now / pi_behav),
    with the proximal log-probs in fp32 also when the update runs in bf16 (no rounding bias)."""
    from charctl.rl.ppo import behaviour_weights

    torch.manual_seed(2)
    cfg = PPOConfig(hidden=[32, 32], action_std=0.1, lr=0.0, epochs=1, minibatch_size=64)
    cfg.update_precision = precision
    model = ActorCritic(4, 2, cfg)
    st = RolloutStorage(2, 64, 4, 2, 0)
    shifts = []
    for _ in range(2):
        obs = torch.randn(64, 4)
        a, logp, v = model.act(obs)
        shift = 0.4 * torch.randn(64)  # the behaviour policy gave these actions other probabilities
        shifts.append(shift)
        st.add(obs, None, a, logp + shift, v, torch.randn(64), torch.zeros(64))
    st.finish(torch.zeros(64), 0.99, 0.95)
    stats = PPO(model, cfg).update(st, stale_behaviour=True)
    assert stats["losses/approx_kl"] == pytest.approx(0.0, abs=1e-7)
    assert stats["losses/clip_frac"] == 0.0
    expected = behaviour_weights(-torch.cat(shifts), torch.zeros(128)).mean()
    assert stats["losses/behaviour_weight"] == pytest.approx(float(expected), rel=1e-5)
