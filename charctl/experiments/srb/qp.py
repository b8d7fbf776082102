"""The QP tracker of paper §7, batched over environments.

Per environment, with contact points p_c (world), COM c, the body's world inertia I and angular
velocity w, the decision variables are the COM acceleration q_dd = (a, w_dot) (world, m/s^2 and
rad/s^2), the contact-force coefficients lambda >= 0 in a linearised friction-cone basis B
(4 edges per point: n +- mu t1, n +- mu t2, so f_c = B_c lambda_c with f_n = sum lambda_c) and an
optional free body torque tau (|tau_i| <= torque_limit while a foot is on the ground, 0 in flight;
torque_limit = 0: contact forces only). Newton-Euler:

    m a           = sum_c B_c lambda_c + m g
    I w_dot + w x I w = sum_c (p_c - c) x B_c lambda_c + tau

    minimise  ||q_dd - q_dd_d||^2_W + force_reg ||lambda / m||^2 + torque_reg ||I^-1 tau||^2.

`full_problem` builds exactly this (variables [q_dd, lambda, tau], 6 equality rows) for tests and
the second-solver check. The hot path (`solve_batch`) substitutes the equalities, which gives an
equivalent problem over x = [lambda, tau] with bound constraints only:

    q_dd = K x + k0,   K = [[B / m, 0], [I^-1 [r]x B, I^-1]],   k0 = [g, -I^-1 (w x I w)]
    min 0.5 x' H x + f' x,  H = K' W K + E,  f = K' W (k0 - q_dd_d),  lb <= x <= ub

H and f are built for all environments at once with numpy; the per-environment solve is one
direct call into daqp's C code (no qpsolvers dispatch in the loop). Swing-foot points get
ub = 0, so every environment has the same 16 + 3 variables.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

GRAVITY = np.array([0.0, -9.81, 0.0])
N_POINTS = 4  # 2 feet x 2 contact points
N_EDGES = 4  # friction-pyramid edges per point
N_LAMBDA = N_POINTS * N_EDGES
N_VARS = N_LAMBDA + 3
INF = 1e30


def friction_basis(mu: float) -> np.ndarray:
    """(3, 4) edges of the linearised friction cone for the ground normal +y (unnormalised:
    the normal component of each edge is 1, so sum(lambda) is the normal force in newtons)."""
    return np.array([[mu, -mu, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0], [0.0, 0.0, mu, -mu]])


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices [v]x."""
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([z, -w, y, w, z, -x, -y, x, z], axis=-1).reshape(v.shape[:-1] + (3, 3))


@dataclass
class QPBatch:
    """Inputs of N tracking QPs (world frame)."""

    points: np.ndarray  # (N, 4, 3) contact points (right heel, right toe, left heel, left toe)
    active: np.ndarray  # (N, 4) bool: point in contact
    com: np.ndarray  # (N, 3)
    inertia: np.ndarray  # (N, 3, 3) world inertia about the COM
    ang_vel: np.ndarray  # (N, 3) world
    acc_des: np.ndarray  # (N, 6) desired [a, w_dot]


@dataclass
class QPParams:
    mass: float
    mu: float
    w_linear: float = 1.0
    w_angular: float = 1.0
    force_reg: float = 1e-6
    torque_limit: float = 0.0
    torque_reg: float = 1.0


def contact_map(batch: QPBatch, params: QPParams) -> tuple[np.ndarray, np.ndarray]:
    """K (N, 6, 19) and k0 (N, 6): q_dd = K x + k0 for x = [lambda (16), tau (3)]."""
    n = batch.com.shape[0]
    basis = friction_basis(params.mu)  # (3, 4)
    big_b = np.zeros((3, N_LAMBDA))
    for c in range(N_POINTS):  # 4 fixed blocks, built once per call (not per env)
        big_b[:, c * N_EDGES : (c + 1) * N_EDGES] = basis
    r = batch.points - batch.com[:, None, :]  # (N, 4, 3)
    moment = np.einsum("ncij,jk->ncik", skew(r), basis)  # (N, 4, 3, 4)
    moment = moment.transpose(0, 2, 1, 3).reshape(n, 3, N_LAMBDA)
    inv_i = np.linalg.inv(batch.inertia)
    k = np.zeros((n, 6, N_VARS))
    k[:, :3, :N_LAMBDA] = big_b / params.mass
    k[:, 3:, :N_LAMBDA] = inv_i @ moment
    k[:, 3:, N_LAMBDA:] = inv_i
    iw = np.einsum("nij,nj->ni", batch.inertia, batch.ang_vel)
    k0 = np.empty((n, 6))
    k0[:, :3] = GRAVITY
    k0[:, 3:] = -np.einsum("nij,nj->ni", inv_i, np.cross(batch.ang_vel, iw))
    return k, k0


def weights(params: QPParams) -> np.ndarray:
    return np.array([params.w_linear] * 3 + [params.w_angular] * 3)


def reduced_problem(batch: QPBatch, params: QPParams):
    """H (N, 19, 19), f (N, 19), lb (N, 19), ub (N, 19), K, k0 of the bound-constrained form."""
    k, k0 = contact_map(batch, params)
    w = weights(params)
    kw = k * w[None, :, None]
    h = np.einsum("nri,nrj->nij", kw, k)
    idx = np.arange(N_LAMBDA)
    h[:, idx, idx] += params.force_reg / params.mass**2
    tau = slice(N_LAMBDA, N_VARS)
    inv_i = k[:, 3:, N_LAMBDA:]
    h[:, tau, tau] += params.torque_reg * np.einsum("nri,nrj->nij", inv_i, inv_i)
    f = np.einsum("nri,nr->ni", kw, k0 - batch.acc_des)
    n = batch.com.shape[0]
    lb = np.zeros((n, N_VARS))
    ub = np.full((n, N_VARS), INF)
    ub[:, :N_LAMBDA] = np.where(np.repeat(batch.active, N_EDGES, axis=1), INF, 0.0)
    limit = np.where(batch.active.any(axis=1), params.torque_limit, 0.0)[:, None]  # no foot down, no body torque
    lb[:, tau], ub[:, tau] = -limit, limit
    return h, f, lb, ub, k, k0


# ---------------------------------------------------------------------------- solvers
def _solve_daqp(h: np.ndarray, f: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, int]:
    """One bound-constrained QP through daqp's C solver directly (x, exit flag; 1 = optimal)."""
    import daqp

    x, _, flag, _ = daqp.solve(h, f, _EMPTY_A, ub, lb)
    return x, int(flag)


def _qpsolvers(name: str) -> Callable:
    def solve(h, f, lb, ub):
        import qpsolvers

        fixed = lb == ub  # swing points / zero torque limit: equality rows (quadprog rejects twin bounds)
        eq = np.eye(f.size)[fixed] if fixed.any() else None
        lo, hi = np.where(fixed, -np.inf, lb), np.where(fixed | (ub >= INF), np.inf, ub)
        x = qpsolvers.solve_qp(h, f, A=eq, b=lb[fixed] if eq is not None else None, lb=lo, ub=hi, solver=name)
        return (x, 1) if x is not None else (np.zeros_like(f), -1)

    return solve


_EMPTY_A = np.zeros((0, N_VARS))
SOLVERS: dict[str, Callable] = {
    "daqp": _solve_daqp,
    "qpsolvers:daqp": _qpsolvers("daqp"),
    "qpsolvers:quadprog": _qpsolvers("quadprog"),
}


def solve_batch(batch: QPBatch, params: QPParams, solver: str = "daqp") -> dict[str, np.ndarray]:
    """Solve the N tracking QPs. Returns q_dd (N, 6), lambda (N, 16), tau (N, 3), contact forces
    per point (N, 4, 3) world newtons, and the solver flags (N,)."""
    h, f, lb, ub, k, k0 = reduced_problem(batch, params)
    solve = SOLVERS[solver]
    n = h.shape[0]
    x = np.zeros((n, N_VARS))
    flags = np.zeros(n, dtype=int)
    for i in range(n):  # tight loop: one C call per environment (H, f, bounds were built batched)
        x[i], flags[i] = solve(h[i], f[i], lb[i], ub[i])
    qdd = np.einsum("nij,nj->ni", k, x) + k0
    lam = x[:, :N_LAMBDA]
    forces = np.einsum("ij,ncj->nci", friction_basis(params.mu), lam.reshape(n, N_POINTS, N_EDGES))
    return {"qdd": qdd, "lambda": lam, "tau": x[:, N_LAMBDA:], "forces": forces, "flags": flags}


def full_problem(batch: QPBatch, params: QPParams, i: int) -> dict[str, np.ndarray]:
    """Environment i's QP in the paper's form over z = [q_dd (6), lambda (16), tau (3)]:
    min 0.5 z'Pz + q'z  s.t.  A z = b (Newton-Euler),  lb <= z <= ub."""
    mass = params.mass
    inertia = batch.inertia[i]
    basis = friction_basis(params.mu)
    r = batch.points[i] - batch.com[i]
    nz = 6 + N_VARS
    a = np.zeros((6, nz))
    a[:3, :3] = mass * np.eye(3)
    a[3:, 3:6] = inertia
    for c in range(N_POINTS):
        cols = slice(6 + c * N_EDGES, 6 + (c + 1) * N_EDGES)
        a[:3, cols] = -basis
        a[3:, cols] = -skew(r[c]) @ basis
    a[3:, 6 + N_LAMBDA :] = -np.eye(3)
    w = batch.ang_vel[i]
    b = np.concatenate([mass * GRAVITY, -np.cross(w, inertia @ w)])
    p = np.zeros((nz, nz))
    p[:6, :6] = np.diag(weights(params))
    p[6 : 6 + N_LAMBDA, 6 : 6 + N_LAMBDA] = params.force_reg / mass**2 * np.eye(N_LAMBDA)
    inv_i = np.linalg.inv(inertia)
    p[6 + N_LAMBDA :, 6 + N_LAMBDA :] = params.torque_reg * inv_i.T @ inv_i
    q = np.zeros(nz)
    q[:6] = -weights(params) * batch.acc_des[i]
    lb = np.full(nz, -np.inf)
    ub = np.full(nz, np.inf)
    lb[6 : 6 + N_LAMBDA] = 0.0
    ub[6 : 6 + N_LAMBDA] = np.where(np.repeat(batch.active[i], N_EDGES), np.inf, 0.0)
    limit = params.torque_limit if batch.active[i].any() else 0.0
    lb[6 + N_LAMBDA :], ub[6 + N_LAMBDA :] = -limit, limit
    fixed = np.flatnonzero(lb == ub)  # swing points / disabled torque: equality rows, not twin bounds
    a = np.vstack([a, np.eye(nz)[fixed]])
    b = np.concatenate([b, lb[fixed]])
    lb[fixed], ub[fixed] = -np.inf, np.inf
    return {"P": p, "q": q, "A": a, "b": b, "lb": lb, "ub": ub}
