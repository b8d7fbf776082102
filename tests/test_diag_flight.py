"""scripts/diag_flight.py: the flight shares of a hand-made hop (the whole body thrown up at 1.5 m/s)."""

from __future__ import annotations

import numpy as np

from charctl.eval.fidelity import foot_sole_heights

from conftest import load_script


def _load_script():
    return load_script("diag_flight")


def _hop(frames_before: int, frames_after: int, v0: float, dt: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Bodies at identity rotations, standing (soles at y = 0), then the whole body in free fall from v0 m/s
    up back to the ground, then standing. Returns (pos, rot, flight frames)."""
    t_flight = 2 * v0 / 9.81
    n = int(t_flight / dt)
    lift = np.concatenate([np.zeros(frames_before), v0 * dt * np.arange(n) - 0.5 * 9.81 * (dt * np.arange(n)) ** 2])
    lift = np.concatenate([np.maximum(lift, 0.0), np.zeros(frames_after)])
    T = len(lift)
    pos = np.zeros((T, 15, 3))
    pos[..., 1] = 1.0 + lift[:, None]
    rot = np.zeros((T, 15, 4))
    rot[..., 3] = 1.0
    pos[..., 1] -= foot_sole_heights(pos[:1], rot[:1]).min()  # soles on the ground while standing
    return pos, rot, n


def test_a_hop_is_airborne_and_ballistic_and_standing_is_neither():
    mod = _load_script()
    dt = 1 / 30
    pos, rot, n = _hop(20, 20, 1.5, dt)  # 0.306 s of flight, 11.5 cm high: 9 frames
    T = len(pos)
    up, ballistic, both, low = mod.flight_shares(pos, rot, dt, 0.0, loop=False)
    lift = pos[:, 0, 1] - pos[0, 0, 1]
    assert up == (lift > 0.05).sum() / T  # the frames more than 5 cm up, by the construction above
    # free fall inside the flight; the two central differences blur up to two frames at each end
    assert 0 < (n - 4) / T <= ballistic <= (n + 2) / T
    assert (n - 4) / T <= both <= up and both <= low <= ballistic
    standing = mod.flight_shares(pos[:20], rot[:20], dt, 0.0, loop=False)
    assert standing == (0.0, 0.0, 0.0, 0.0)


def test_step_timing_of_a_hop_counts_one_landing_per_foot_and_the_flight_length():
    mod = _load_script()
    dt = 1 / 30
    pos, rot, n = _hop(20, 20, 1.5, dt)
    T = len(pos)
    lift = pos[:, 0, 1] - pos[0, 0, 1]
    up = int((lift >= 0.02).sum())  # soles more than 2 cm up: both feet, the whole body is lifted
    rate, flight = mod.step_timing(pos, rot, dt, 0.0)
    assert rate == 2 / (T * dt)  # both feet come down once, at the landing
    assert flight == up * dt
    assert 0 < up < n  # the flight counted at 2 cm is shorter than the whole ballistic arc
    assert mod.step_timing(pos[:20], rot[:20], dt, 0.0) == (0.0, 0.0)  # standing: no touchdown, no flight
