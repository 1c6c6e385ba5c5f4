"""iLQR against direct collocation: the swing-ups from the straight guess and 20 random guesses, then tracked.

The iLQR is defined here (the package plans by collocation alone; bench/README.md,
"iLQR beside collocation", says why). It is Li and Todorov's iterative LQR on the RK4
step of the system's derived dynamics (``casadi_dynamics``, exact Jacobians by CasADi)
over the plan's ``N`` intervals. The input is linear over each interval (first-order
hold, so the plan is a ``Trajectory`` whose quadratic input between knots is exact): the
state is augmented by the input at the interval's start, the control is the input at its
end, its first value 0. The input limits are honoured by the box-constrained backward
pass of Tassa, Mansard and Todorov's control-limited DDP (the clamped inputs' feedback
rows are zero); the final state and the task's state bounds by an augmented Lagrangian
(multipliers updated, penalty raised, until the final state is within ``tol`` of the
goal). The cost is the collocation's effort, ``integral of sum (u_i / scale_i)^2 dt``,
exact for the linear input (Simpson's rule).

    nice -n 10 .venv/bin/python bench/bench_ilqr.py [--only acrobot,cartpole,...] [--starts 200]

Each case plans the same problem both ways: N = 60 intervals of a fixed duration, the
least effort (integral of (u / scale)^2), the input limits, the cart-pole's track less
the default margin; collocation by ``plan`` (Hermite-Simpson, IPOPT), iLQR by
``plan_ilqr`` (RK4 steps, control-limited backward pass, the final state by an augmented
Lagrangian; at most 1000 backward passes and 30 s). For each method: the number converged
of the straight guess and of 20 seeded random guesses, the median and worst CPU time, the
median final-state miss (largest component), the median effort of the converged plans.
Then each method's plan from the straight guess is tracked by the time-varying LQR (its
catch on) from *starts* noisy starts about hanging (+-0.05 rad, +-0.1 rad/s), with the
rig's sensor and process noise, 15 s: the fraction that ends balanced and the median time
to balance, as bench_tracking.py measures them, nominal and with every mass drawn within
+-20 % per run. Last, collocation polishing the iLQR's plan (``--guess`` its file).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from equilibrist import get_system
from equilibrist.control.trajopt import (
    TIMED_OUT,
    Trajectory,
    casadi_dynamics,
    check_guess,
    plan,
    require_casadi,
)
from equilibrist.control.tvlqr import build_request
from equilibrist.controllers.kinds import ControllerRequest
from equilibrist.errors import ControllerError, DesignError
from equilibrist.numeric.system import System
from equilibrist.sim import Noise, simulate_batch
from equilibrist.sim.batch import monte_carlo
from equilibrist.tasks import get_task, planning_bounds

#: Backward passes at most between two updates of the multipliers.
INNER = 100


@dataclass
class _Problem:
    """The discrete problem on the augmented state ``z = (x, u_prev)``."""

    step: Any  # CasADi: (z, v) -> z+
    jac: Any  # CasADi, mapped over N: (Z, V) -> (A stacked, B stacked)
    n: int
    m: int
    N: int
    h: float
    w: np.ndarray  # effort weights 1 / scale^2
    lo: np.ndarray
    hi: np.ndarray
    goal: np.ndarray
    blo: np.ndarray  # state bounds (-inf, inf where none)
    bhi: np.ndarray


def _problem(system: System, N: int, h: float, goal: np.ndarray,
             bounds: Mapping[str, tuple[float, float]], lo: np.ndarray,
             hi: np.ndarray) -> _Problem:
    ca = require_casadi()
    n, m = system.n_states, system.n_inputs
    f = casadi_dynamics(system)
    z = ca.SX.sym("z", n + m)
    v = ca.SX.sym("v", m)
    x, u0 = z[:n], z[n:]
    um = 0.5 * (u0 + v)
    k1 = f(x, u0)
    k2 = f(x + 0.5 * h * k1, um)
    k3 = f(x + 0.5 * h * k2, um)
    k4 = f(x + h * k3, v)
    znext = ca.vertcat(x + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4), v)
    step = ca.Function("step", [z, v], [znext]).expand()
    jac = ca.Function("step_jacobians", [z, v], [ca.jacobian(znext, z), ca.jacobian(znext, v)]).expand()
    scales = np.array([float(system.spec.design_scales.get(i, 1.0)) or 1.0
                       for i in system.input_names])
    blo, bhi = np.full(n, -np.inf), np.full(n, np.inf)
    for name, (a, b) in bounds.items():
        k = system.state_index(name)
        blo[k], bhi[k] = a, b
    return _Problem(step, jac.map(N), n, m, N, h, 1.0 / scales**2, lo, hi, goal, blo, bhi)


def _rollout(p: _Problem, z0: np.ndarray, V: np.ndarray, Z: np.ndarray | None = None,
             d: np.ndarray | None = None, K: np.ndarray | None = None,
             alpha: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The states and controls of a forward pass: *V* alone, or the feedback policy
    ``v_k = V_k + alpha d_k + K_k (z_k - Z_k)`` about the nominal *Z*, clamped."""
    Zn = np.empty((p.N + 1, p.n + p.m))
    Vn = np.empty_like(V)
    Zn[0] = z0
    for k in range(p.N):
        vk = V[k] if Z is None else V[k] + alpha * d[k] + K[k] @ (Zn[k] - Z[k])  # type: ignore[index]
        Vn[k] = np.clip(vk, p.lo, p.hi)
        Zn[k + 1] = np.asarray(p.step(Zn[k], Vn[k])).reshape(-1)
    return Zn, Vn


def _costs(p: _Problem, Z: np.ndarray, V: np.ndarray, lam: np.ndarray, mu: np.ndarray,
           rho: float) -> tuple[float, float]:
    """The effort and the augmented Lagrangian's total of a pass."""
    U0 = Z[:-1, p.n:]
    effort = float(np.sum(p.w * (U0**2 + (U0 + V)**2 + V**2)) * p.h / 6)
    e = Z[-1, :p.n] - p.goal
    total = effort + float(lam @ e) + 0.5 * rho * float(e @ e)
    c = _bound_violation(p, Z[1:, :p.n], mu, rho)
    total += float(np.sum(np.maximum(0.0, mu + rho * c)**2 - mu**2) / (2 * rho))
    return effort, total


def _bound_violation(p: _Problem, X: np.ndarray, mu: np.ndarray, rho: float) -> np.ndarray:
    """``c(x) <= 0`` of the state bounds at knots 1..N: (N, 2n), low then high."""
    with np.errstate(invalid="ignore"):
        c = np.hstack([p.blo - X, X - p.bhi])
    return np.where(np.isfinite(c), c, -np.inf)


def _box_qp(Quu: np.ndarray, Qu: np.ndarray, Qux: np.ndarray, v: np.ndarray,
            lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The step ``d`` and gain ``K`` of one knot: the box-constrained QP's minimizer within
    ``lo <= v + d <= hi`` (Tassa et al.'s control-limited DDP; scipy's bounded least squares
    for several inputs), the clamped inputs' rows of ``K`` zero."""
    m = Qu.size
    if m == 1:  # one input: the Newton step clamped, its gain zero where it clamps
        step = -Qu[0] / Quu[0, 0]
        if not lo[0] <= v[0] + step <= hi[0]:
            clamped_step = min(max(v[0] + step, lo[0]), hi[0]) - v[0]
            return np.array([clamped_step]), np.zeros((1, Qux.shape[1]))
        return np.array([step]), -Qux / Quu[0, 0]
    from scipy.optimize import lsq_linear

    # 0.5 d' Quu d + Qu' d = 0.5 |L' d + L^-1 Qu|^2 + const, Quu = L L': a bounded least squares
    L = np.linalg.cholesky(Quu)
    d = lsq_linear(L.T, -np.linalg.solve(L, Qu), bounds=(lo - v, hi - v), method="bvls",
                   tol=1e-12).x
    free = (v + d > lo + 1e-12) & (v + d < hi - 1e-12)
    K = np.zeros((m, Qux.shape[1]))
    if free.any():
        K[free] = -np.linalg.solve(Quu[np.ix_(free, free)], Qux[free])
    return d, K


def _backward(p: _Problem, Z: np.ndarray, V: np.ndarray, lam: np.ndarray, mu: np.ndarray,
              rho: float, reg: float) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Feed-forward steps, gains and the expected decrease; None where ``Quu`` is not
    positive definite at this regularization."""
    n, m, N = p.n, p.m, p.N
    A, B = (np.asarray(a) for a in p.jac(Z[:-1].T, V.T))
    A = A.reshape(n + m, N, n + m)
    B = B.reshape(n + m, N, m)
    e = Z[-1, :n] - p.goal
    Vz = np.zeros(n + m)
    Vzz = np.zeros((n + m, n + m))
    Vz[:n] = lam + rho * e
    Vzz[:n, :n] = rho * np.eye(n)
    c = _bound_violation(p, Z[1:, :n], mu, rho)
    act = (mu + rho * c) > 0
    g = np.where(act, mu + rho * c, 0.0)
    W = np.diag(p.w) * (p.h / 6)
    d = np.zeros((N, m))
    K = np.zeros((N, m, n + m))
    dJ = 0.0
    for k in range(N - 1, -1, -1):
        # the state bounds' terms at knot k + 1 enter its value function
        Vz[:n] += g[k, n:] - g[k, :n]
        Vzz[:n, :n] += np.diag(rho * (act[k, :n] + act[k, n:]))
        u0, vk = Z[k, n:], V[k]
        Ak, Bk = A[:, k, :], B[:, k, :]
        Qz = Ak.T @ Vz
        Qz[n:] += W @ (4 * u0 + 2 * vk)
        Qv = Bk.T @ Vz + W @ (2 * u0 + 4 * vk)
        Qzz = Ak.T @ Vzz @ Ak
        Qzz[n:, n:] += 4 * W
        Qvz = Bk.T @ Vzz @ Ak
        Qvz[:, n:] += 2 * W
        Qvv = Bk.T @ Vzz @ Bk + 4 * W + reg * np.eye(m)
        if (Qvv[0, 0] <= 0 if m == 1 else np.any(np.linalg.eigvalsh(Qvv) <= 0)):
            return None
        d[k], K[k] = _box_qp(Qvv, Qv, Qvz, vk, p.lo, p.hi)
        dJ += float(d[k] @ Qv + 0.5 * d[k] @ Qvv @ d[k])
        Vz = Qz + K[k].T @ Qvv @ d[k] + K[k].T @ Qv + Qvz.T @ d[k]
        Vzz = Qzz + K[k].T @ Qvv @ K[k] + K[k].T @ Qvz + Qvz.T @ K[k]
        Vzz = 0.5 * (Vzz + Vzz.T)
    return d, K, dJ


def _inner(p: _Problem, Z: np.ndarray, V: np.ndarray, lam: np.ndarray, mu: np.ndarray,
           rho: float, max_iterations: int, deadline: float
           ) -> tuple[np.ndarray, np.ndarray, int]:
    """iLQR on the augmented Lagrangian with fixed multipliers: the pass it ends on and
    the iterations it took (Levenberg-Marquardt regularization, a backtracking line search)."""
    reg = 1e-6
    total = _costs(p, Z, V, lam, mu, rho)[1]
    for it in range(1, max_iterations + 1):
        back = _backward(p, Z, V, lam, mu, rho, reg)
        if back is None:
            reg = max(reg * 10, 1e-6)
            if reg > 1e10:
                return Z, V, it
            continue
        d, K, dJ = back
        if -dJ < 1e-7 * (1 + abs(total)):
            return Z, V, it
        for alpha in (1.0, 0.5, 0.25, 0.1, 0.03, 0.01, 1e-3):
            with np.errstate(over="ignore", invalid="ignore"):  # a diverging pass is refused
                Zn, Vn = _rollout(p, Z[0], V, Z, d, K, alpha)
                new = _costs(p, Zn, Vn, lam, mu, rho)[1] if np.all(np.isfinite(Zn)) else math.inf
            if new < total - 1e-4 * alpha * -dJ:
                break
        else:
            reg *= 10
            if reg > 1e10:
                return Z, V, it
            continue
        improvement = total - new
        Z, V, total = Zn, Vn, new
        reg = max(reg / 3, 1e-9)
        if improvement < 1e-7 * (1 + abs(total)) or time.monotonic() > deadline:
            return Z, V, it
    return Z, V, max_iterations


def _guess_inputs(system: System, guess: str | Trajectory, N: int, duration: float,
                  seed: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The controls of the first pass: zero (``straight``), uniform within the limits
    (``random``, the collocation's inputs of the same seed) or a plan's, resampled."""
    m = system.n_inputs
    if isinstance(guess, Trajectory):
        check_guess(guess, n=system.n_states, m=m, duration_max=None)
        tt = np.linspace(0.0, guess.duration, N + 1)[1:] + guess.times[0]
        resampled: np.ndarray = np.clip(guess.input_at(tt).reshape(N, m), lo, hi)
        return resampled
    if guess == "straight":
        return np.zeros((N, m))
    if guess == "random":
        rng = np.random.default_rng(seed)
        rng.normal(0.0, 1.0, (N + 1, system.n_states))  # the collocation's state noise
        inputs: np.ndarray = rng.uniform(lo, hi, (N + 1, m))[1:]
        return inputs
    raise DesignError(f"guess = {guess!r}: expected random, straight or a trajectory file")


def plan_ilqr(system: System, *, start: np.ndarray, goal: np.ndarray, knots: int = 60,
              duration: float = 5.0, guess: str | Trajectory = "straight", seed: int = 0,
              bounds: Mapping[str, tuple[float, float]] | None = None,
              max_iterations: int = 3000, max_time: float | None = 120.0,
              tol: float = 1e-6) -> Trajectory:
    """Plan a motion of *system* from *start* to *goal* by iterative LQR (see the module).

    *knots* intervals of a fixed *duration*; *guess* the first pass's inputs; *bounds* the
    states' ``{name: (low, high)}``; *max_iterations* the backward passes in all;
    *max_time* wall-clock seconds. Converged when the final state is within *tol* of
    *goal* (every component) and the bounds are kept to *tol*; ``max_defect`` is that
    largest miss (the knots are the RK4 rollout itself, the start exact).
    """
    if not isinstance(knots, int) or not 4 <= knots <= 2000:
        raise DesignError(f"knots = {knots!r}: expected a whole number from 4 to 2000")
    if not (math.isfinite(duration) and 0 < duration <= 1e4):
        raise DesignError(f"duration = {duration!r}: expected seconds in (0, 10000]")
    n, m, N = system.n_states, system.n_inputs, knots
    if m == 0:
        raise DesignError(f"{system.key} has no input: there is no motion to plan")
    start = np.asarray(start, dtype=float).reshape(n)
    goal = np.asarray(goal, dtype=float).reshape(n)
    lo = np.array([float(system.params[f"{i}_min"]) for i in system.input_names])
    hi = np.array([float(system.params[f"{i}_max"]) for i in system.input_names])
    V0 = _guess_inputs(system, guess, N, duration, seed, lo, hi)
    t0 = time.process_time()
    deadline = math.inf if max_time is None else time.monotonic() + max_time
    p = _problem(system, N, duration / N, goal, bounds or {}, lo, hi)
    Z, V = _rollout(p, np.concatenate([start, np.zeros(m)]), V0)
    lam, mu, rho = np.zeros(n), np.zeros((N, 2 * n)), 10.0
    iterations, miss = 0, math.inf
    while iterations < max_iterations and time.monotonic() < deadline:
        Z, V, it = _inner(p, Z, V, lam, mu, rho, min(INNER, max_iterations - iterations),
                          deadline)
        iterations += it
        e = Z[-1, :n] - goal
        c = _bound_violation(p, Z[1:, :n], mu, rho)
        new_miss = max(float(np.max(np.abs(e))), float(np.max(c, initial=0.0)))
        if new_miss < tol:
            miss = new_miss
            break
        lam = lam + rho * e
        mu = np.maximum(0.0, mu + rho * c)
        if new_miss > 0.25 * miss:
            rho = min(rho * 10, 1e9)
        miss = new_miss
    solve_time = time.process_time() - t0
    status = ("converged" if miss < tol else TIMED_OUT if time.monotonic() >= deadline
              else "not converged")
    inputs = Z[:, n:].copy()
    effort = _costs(p, Z, V, np.zeros(n), mu * 0, rho)[0]
    return Trajectory(
        system=system.key, params=dict(system.params), state_names=system.state_names,
        input_names=system.input_names, times=np.linspace(0.0, duration, N + 1),
        states=Z[:, :n].copy(), inputs=inputs, mid_inputs=0.5 * (inputs[:-1] + inputs[1:]),
        converged=miss < tol, cost=effort, max_defect=miss, solve_time=solve_time,
        iterations=iterations, solver="ilqr (CasADi RK4, control-limited, augmented Lagrangian)",
        settings={"knots": N, "minimize": "effort", "method": "ilqr",
                  "guess": guess if isinstance(guess, str) else "file", "seed": seed,
                  "duration": duration, "duration_max": None,
                  "bounds": {k: list(v) for k, v in (bounds or {}).items()},
                  "start": start.tolist(), "goal": goal.tolist()},
        system_digest=system.digest, status=status)


DRAKE = {"m1": 1.0, "m2": 1.0, "l1": 1.0, "l2": 2.0, "lc1": 0.5, "lc2": 1.0, "I1": 0.083,
         "I2": 0.33, "b1": 0.1, "b2": 0.1, "g": 9.81, "tau_min": -8.0, "tau_max": 8.0}
#: label: (system, parameters, duration [s])
CASES = {
    "acrobot": ("acrobot", {}, 4.0),
    "cartpole": ("cartpole", {}, 4.0),
    "acrobot-drake-4s": ("acrobot", DRAKE, 4.0),
    "dfki_acrobot": ("dfki_double_pendulum", {}, 5.0),
}


def solve(method: str, system, task, bounds, duration: float, guess: str, seed: int):
    if method == "collocation":
        return plan(system, start=task.start, goal=task.x_op, knots=60, duration=duration,
                    guess=guess, seed=seed, bounds=bounds)
    return plan_ilqr(system, start=task.start, goal=task.x_op, knots=60, duration=duration,
                     guess=guess, seed=seed, bounds=bounds, max_iterations=1000, max_time=30.0)


def miss(traj, goal: np.ndarray) -> float:
    return float(np.max(np.abs(traj.states[-1] - goal)))


def tracked(system, task, traj, label: str, starts: int) -> str:
    path = traj.save(f"/tmp/equilibrist_bench_ilqr_{label}.npz")
    try:
        ctrl = build_request(ControllerRequest(system=system, rate=float(system.spec.control_rate),
                                               options={"trajectory": str(path)}))
    except ControllerError as exc:
        return f"no tracker: {exc}"
    rng = np.random.default_rng(2026)
    x0 = np.tile(np.asarray(task.start, dtype=float), (starts, 1))
    for i, unit in enumerate(system.state_units):
        half = 0.05 if unit == "rad" else 0.1 if unit == "rad/s" else 0.0
        x0[:, i] += rng.uniform(-half, half, starts)
    noise = Noise.from_spec(system, outputs=ctrl.output_names, rate=ctrl.rate)
    batch = simulate_batch(system, ctrl, runs=starts, x0=x0, duration=15.0, noise=noise, seed=7,
                           region=dict(task.region))
    spread = {p.name: 0.2 for p in system.spec.all_parameters if p.unit == "kg"}
    mc = monte_carlo(system, ctrl, spread=spread, runs=starts, x0=x0, duration=15.0,
                     noise=noise, seed=7, region=dict(task.region)).batch
    t50, m50 = batch.time_to_balance(0.5), mc.time_to_balance(0.5)
    return (f"tracked: fraction_balanced {batch.fraction_balanced:.3f} ({batch.balanced}/"
            f"{batch.runs}), time to balance median {'-' if t50 is None else f'{t50:.2f} s'}; "
            f"masses +-20 %: {mc.fraction_balanced:.3f}, {'-' if m50 is None else f'{m50:.2f} s'}")


def case(label: str, starts: int) -> None:
    name, params, duration = CASES[label]
    system = get_system(name, **params)
    task = get_task(system, "swingup")
    bounds = planning_bounds(task, 0.3)
    print(f"{label}: {system.key}, N = 60, {duration:g} s, limits "
          + ", ".join(f"|{i}| <= {system.params[i + '_max']:g}" for i in system.input_names))
    solve("collocation", system, task, bounds, duration, "straight", 0)  # CasADi's set-up
    for method in ("collocation", "ilqr"):
        straight = solve(method, system, task, bounds, duration, "straight", 0)
        runs = [solve(method, system, task, bounds, duration, "random", s) for s in range(20)]
        ok = [t for t in runs if t.converged]
        times = [t.solve_time for t in runs]
        print(f"  {method:<11} straight: {'converged' if straight.converged else 'NOT converged'}"
              f" in {straight.solve_time:.3f} s, {straight.iterations} iterations, miss "
              f"{miss(straight, task.x_op):.1e}, effort {straight.cost:.4g}")
        print(f"  {'':<11} random: {len(ok)}/20 converged; CPU median {statistics.median(times):.3f}"
              f" s, worst {max(times):.3f} s; iterations median "
              f"{statistics.median(t.iterations for t in runs):.0f}; miss median "
              f"{statistics.median(miss(t, task.x_op) for t in runs):.1e}; effort of the "
              f"converged median {statistics.median(t.cost for t in ok) if ok else float('nan'):.4g}"
              f" (min {min((t.cost for t in ok), default=float('nan')):.4g})")
        if straight.converged and starts:
            print(f"  {'':<11} {tracked(system, task, straight, f'{label}_{method}', starts)}")
        if method == "ilqr" and straight.converged:
            polished = plan(system, start=task.start, goal=task.x_op, knots=60,
                            duration=duration, guess=straight, bounds=bounds)
            print(f"  {'':<11} collocation from this plan: "
                  f"{'converged' if polished.converged else 'NOT converged'} in "
                  f"{polished.solve_time:.3f} s, {polished.iterations} iterations, effort "
                  f"{polished.cost:.4g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default=",".join(CASES))
    parser.add_argument("--starts", type=int, default=200)
    args = parser.parse_args()
    print(f"load average of the machine: {os.getloadavg()[0]:.1f} (2 cores)")
    for label in args.only.split(","):
        case(label, args.starts)
    print(f"load average of the machine after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
