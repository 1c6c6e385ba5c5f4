"""Trajectory optimization: a motion planned under the rig's real limits, by direct collocation.

The plan is a Hermite-Simpson collocation (separated form) of the system's
derived dynamics ``M(q) q_ddot = F(q, q_dot, u)``: states at ``N + 1`` knots,
inputs at the knots and the midpoints, the defects

    x_mid   = (x_k + x_k+1) / 2 + h / 8 (f_k - f_k+1)
    x_k+1   = x_k + h / 6 (f_k + 4 f_mid + f_k+1)

as equality constraints, with ``f`` the system's own equations translated
exactly into CasADi (``q_ddot`` solved from ``M`` at each point), so the NLP
solver (IPOPT) gets exact first and second derivatives and their sparsity.
Hard input limits, the task's state bounds (the cart-pole's track), a fixed
or free final time, and a cost of effort (``integral of (u / scale)^2``) or
of time. Needs CasADi: ``pip install 'equilibrist[trajopt]'``.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
import types
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from equilibrist.errors import DesignError
from equilibrist.numeric.system import System

GUESSES = ("random", "straight")
MINIMIZE = ("effort", "time")
FORMAT = "equilibrist-trajectory-1"
#: The wall-clock seconds a solve may take by default (``plan(max_time=...)``, ``--max-time``).
MAX_TIME = 120.0
#: The ``status`` of a plan whose solve reached its ``max_time`` (IPOPT's own word for it).
TIMED_OUT = "Maximum_WallTime_Exceeded"


def require_casadi() -> types.ModuleType:
    try:
        import casadi
    except ImportError:
        raise DesignError("trajectory optimization needs CasADi with IPOPT: "
                          "pip install 'equilibrist[trajopt]'") from None
    return casadi


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A planned motion: states at the knots, inputs at the knots and midpoints.

    Between knots the states are the cubic Hermite interpolant of the knots'
    states and rates, the inputs the quadratic through the knot, midpoint
    and knot (:meth:`input_at`).
    """

    system: str
    params: Mapping[str, float]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    times: np.ndarray  # (N + 1,)
    states: np.ndarray  # (N + 1, n)
    inputs: np.ndarray  # (N + 1, m)
    mid_inputs: np.ndarray  # (N, m)
    converged: bool
    cost: float
    max_defect: float
    solve_time: float
    iterations: int
    solver: str
    settings: Mapping[str, object] = field(default_factory=dict)
    system_digest: str | None = None
    #: IPOPT's return status (``Solve_Succeeded``...), :data:`TIMED_OUT` where the solve
    #: reached its ``max_time``; empty for a trajectory read from a file.
    status: str = ""

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0])

    @property
    def knots(self) -> int:
        return int(self.times.size - 1)

    @property
    def peak_input(self) -> dict[str, float]:
        both = np.vstack([self.inputs, self.mid_inputs])
        return {n: float(np.max(np.abs(both[:, i]))) for i, n in enumerate(self.input_names)}

    def input_at(self, t: float | np.ndarray) -> np.ndarray:
        """The planned input at time(s) *t* (held at the ends outside the plan)."""
        tt = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), self.times[0], self.times[-1])
        k = np.clip(np.searchsorted(self.times, tt, side="right") - 1, 0, self.knots - 1)
        h = self.times[k + 1] - self.times[k]
        s = ((tt - self.times[k]) / h)[:, None]
        u0, um, u1 = self.inputs[k], self.mid_inputs[k], self.inputs[k + 1]
        out: np.ndarray = ((2 * (s - 0.5) * (s - 1)) * u0 + (-4 * s * (s - 1)) * um
                           + (2 * s * (s - 0.5)) * u1)
        return out if np.ndim(t) else out[0]

    def summary(self) -> dict[str, object]:
        return {"converged": self.converged, "duration": self.duration, "cost": self.cost,
                "peak_input": self.peak_input, "max_defect": self.max_defect,
                "solve_time": self.solve_time, "iterations": self.iterations,
                "solver": self.solver, "knots": self.knots}

    def save(self, path: str | Path) -> Path:
        """Write the trajectory (``.npz``: the arrays, the system, its parameters, the settings)."""
        import json

        from equilibrist.atomic import atomic_path

        p = Path(path)
        if p.suffix.lower() != ".npz":
            raise DesignError(f"{p}: a trajectory is written as .npz")
        meta = {"format": FORMAT, "system": self.system, "system_digest": self.system_digest,
                "params": dict(self.params), "state_names": list(self.state_names),
                "input_names": list(self.input_names), "settings": dict(self.settings),
                **{k: v for k, v in self.summary().items() if k != "peak_input"}}
        with atomic_path(p) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, meta=json.dumps(meta), times=self.times, states=self.states,
                     inputs=self.inputs, mid_inputs=self.mid_inputs)
        return p


def casadi_dynamics(system: System) -> Any:
    """``f(x, u)`` of *system* as a CasADi function: its derived ``M`` and ``F``, parameters bound."""
    import sympy as sp

    ca = require_casadi()
    sym = system.symbolic
    n, m = system.n_states, system.n_inputs
    nq = sym.n_q
    x = ca.SX.sym("x", n)
    u = ca.SX.sym("u", m)
    values = {s: float(system.params[str(s)]) for s in sym.params if str(s) in system.params}
    subs = {**{s: x[i] for i, s in enumerate(sym.states)}, **{s: u[i] for i, s in enumerate(sym.inputs)}}
    printer = {"sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "exp": ca.exp, "log": ca.log,
               "sqrt": ca.sqrt, "Abs": ca.fabs, "atan2": ca.atan2, "atan": ca.atan,
               "asin": ca.asin, "acos": ca.acos, "tanh": ca.tanh, "sign": ca.sign,
               "sinh": ca.sinh, "cosh": ca.cosh}
    args = [*sym.states, *sym.inputs]
    if sym.M is None or sym.F is None or nq * 2 != n:
        expr = sym.f.subs(values)
        fn = sp.lambdify(args, list(expr), modules=[printer, "math"])
        return ca.Function("f", [x, u], [ca.vertcat(*fn(*[subs[a] for a in args]))])
    M = sp.lambdify(args, sym.M.subs(values).tolist(), modules=[printer, "math"])
    F = sp.lambdify(args, list(sym.F.subs(values)), modules=[printer, "math"])
    vals = [subs[a] for a in args]
    Mx = ca.SX(nq, nq)
    for i, row in enumerate(M(*vals)):
        for j, v in enumerate(row):
            Mx[i, j] = v
    qdd = ca.solve(Mx, ca.vertcat(*F(*vals)))
    return ca.Function("f", [x, u], [ca.vertcat(x[nq:], qdd)])


#: IPOPT through CasADi: the NLP expanded to scalar expressions (SX), whose derivatives
#: evaluate about twice as fast as the matrix graph's; the barrier parameter adaptive
#: (Mehrotra's probing), which takes fewer iterations on these problems (the acrobot's 54 to
#: 41, the cart-pole's minimum time 112 to 59, medians of random guesses; bench/README.md).
IPOPT_OPTIONS = {"print_time": False, "expand": True}
IPOPT_SETTINGS = {"print_level": 0, "sb": "yes", "tol": 1e-8, "constr_viol_tol": 1e-8,
                  "mu_strategy": "adaptive"}
#: Problems built, by what shapes them (a plan from another start or guess reuses one).
_PROBLEMS: dict[tuple[object, ...], _Problem] = {}
_PROBLEMS_LOCK = threading.Lock()


@dataclass(eq=False)
class _Problem:
    """A transcription built once: its start and goal are parameters, its guess set per solve."""

    f: Any
    opti: Any
    X: Any
    U: Any
    Um: Any
    T: Any
    start: Any
    goal: Any
    lock: threading.Lock = field(default_factory=threading.Lock)
    max_iterations: int = -1
    stopper: Any = None  # IPOPT's iteration callback (_stopper), made with the solver


def _problem(system: System, N: int, duration: float | None, duration_max: float | None,
             minimize: str, bounds: Mapping[str, tuple[float, float]], lo: np.ndarray,
             hi: np.ndarray, state_cost: Mapping[str, float] | None = None,
             input_rate_cost: Mapping[str, float] | None = None) -> _Problem:
    """The collocation problem of *system* (cached by everything that shapes it)."""
    key = (system.digest, tuple(sorted((k, float(v)) for k, v in system.params.items())), N,
           duration, duration_max, minimize,
           tuple(sorted((k, float(a), float(b)) for k, (a, b) in bounds.items())),
           tuple(sorted((k, float(v)) for k, v in (state_cost or {}).items())),
           tuple(sorted((k, float(v)) for k, v in (input_rate_cost or {}).items())))
    with _PROBLEMS_LOCK:
        if key in _PROBLEMS:
            return _PROBLEMS[key]
    ca = require_casadi()
    n, m = system.n_states, system.n_inputs
    f = casadi_dynamics(system)
    opti = ca.Opti()
    X = opti.variable(n, N + 1)
    U = opti.variable(m, N + 1)
    Um = opti.variable(m, N)
    start = opti.parameter(n)
    goal = opti.parameter(n)
    T = opti.variable() if duration is None else duration
    t_max = duration if duration is not None else duration_max
    assert t_max is not None
    h = T / N
    scales = np.array([float(system.spec.design_scales.get(i, 1.0)) or 1.0 for i in system.input_names])
    Fk = f.map(N + 1)(X, U)
    Xm = 0.5 * (X[:, :-1] + X[:, 1:]) + (h / 8) * (Fk[:, :-1] - Fk[:, 1:])
    Fm = f.map(N)(Xm, Um)
    opti.subject_to(X[:, 1:] - X[:, :-1] == (h / 6) * (Fk[:, :-1] + 4 * Fm + Fk[:, 1:]))
    opti.subject_to(X[:, 0] == start)
    opti.subject_to(X[:, N] == goal)
    for i in range(m):
        opti.subject_to(opti.bounded(lo[i], U[i, :], hi[i]))
        opti.subject_to(opti.bounded(lo[i], Um[i, :], hi[i]))
    for name, (a, b) in bounds.items():
        k = system.state_index(name)
        opti.subject_to(opti.bounded(a, X[k, :], b))
        opti.subject_to(opti.bounded(a, Xm[k, :], b))
    if duration is None:
        opti.subject_to(opti.bounded(0.05 * t_max, T, t_max))
    w = 1.0 / scales**2
    effort = 0
    for i in range(m):
        effort = effort + w[i] * (h / 6) * (ca.sumsqr(U[i, :-1]) + 4 * ca.sumsqr(Um[i, :])
                                            + ca.sumsqr(U[i, 1:]))
    # The states' weighted squares about the goal, integrated as the effort is (Simpson's
    # rule on the knots and midpoints): only when asked, so the default problem is unchanged.
    for name, weight in (state_cost or {}).items():
        k = system.state_index(name)
        effort = effort + float(weight) * (h / 6) * (
            ca.sumsqr(X[k, :-1] - goal[k]) + 4 * ca.sumsqr(Xm[k, :] - goal[k])
            + ca.sumsqr(X[k, 1:] - goal[k]))
    # The inputs' rates squared, from the differences of the samples (knot, midpoint, knot...)
    # half an interval apart: a smoother motor command.
    for name, weight in (input_rate_cost or {}).items():
        i = system.input_names.index(name)
        samples = ca.vertcat(ca.vec(ca.vertcat(U[i, :-1], Um[i, :])), U[i, N])
        effort = effort + float(weight) * ca.sumsqr(ca.diff(samples)) / (h / 2)
    opti.minimize(effort if minimize == "effort" else T + 1e-6 * effort)
    problem = _Problem(f, opti, X, U, Um, T, start, goal)
    with _PROBLEMS_LOCK:
        if len(_PROBLEMS) >= 16:
            _PROBLEMS.pop(next(iter(_PROBLEMS)))
        return _PROBLEMS.setdefault(key, problem)


def plan(system: System, *, start: np.ndarray, goal: np.ndarray, knots: int = 60,
         duration: float | None = None, duration_max: float | None = None,
         minimize: str = "effort", guess: str | Trajectory = "straight", seed: int = 0,
         bounds: Mapping[str, tuple[float, float]] | None = None,
         max_iterations: int = 3000, max_time: float | None = MAX_TIME,
         state_cost: Mapping[str, float] | None = None,
         input_rate_cost: Mapping[str, float] | None = None) -> Trajectory:
    """Plan a motion of *system* from *start* to *goal* (absolute states).

    Parameters
    ----------
    knots : int
        Collocation intervals ``N``.
    duration, duration_max : float
        A fixed final time, or a free one in ``[0.05 duration_max, duration_max]`` (one
        of the two).
    minimize : ``"effort"`` or ``"time"``
        ``integral of sum (u_i / scale_i)^2 dt`` (scales: the Bryson scales of the
        inputs) or the final time.
    guess : ``"straight"``, ``"random"`` or a :class:`Trajectory`
        The initial guess: the straight line from start to goal with zero
        input; a seeded random one (*seed*); or a trajectory (interpolated,
        checked by :func:`check_guess`).
    bounds : mapping
        ``{state: (low, high)}`` the motion must keep (the task's region).
    max_iterations : int
        IPOPT's iterations at most.
    state_cost : mapping, optional
        ``{state: weight}``: adds ``integral of weight (x_i - goal_i)^2 dt`` to the effort
        (the rates' squares with a goal at rest: a plan that moves less fast). Weights are
        non-negative; none by default.
    input_rate_cost : mapping, optional
        ``{input: weight}``: adds ``integral of weight (du_i/dt)^2 dt`` (from the differences
        of the input's samples, half an interval apart): a smoother command. None by default.
    max_time : float or None
        Wall-clock seconds the solve may take, the solver's set-up for a new shape of
        problem included (default :data:`MAX_TIME`, 120; None: no limit). A solve
        stopped there is not converged, its ``status`` :data:`TIMED_OUT`.

    The plan's first and last knots are *start* and *goal* exactly (IPOPT meets them
    to its tolerance; its round-off, such as a cart at ``-1e-32`` m, is not kept).
    Ctrl-C (on the command line SIGTERM too) stops IPOPT at its next iteration and
    is raised as ``KeyboardInterrupt``.
    """
    require_casadi()
    if minimize not in MINIMIZE:
        raise DesignError(f"minimize = {minimize!r}: expected one of {', '.join(MINIMIZE)}")
    if not isinstance(knots, int) or not 4 <= knots <= 2000:
        raise DesignError(f"knots = {knots!r}: expected a whole number from 4 to 2000")
    if (duration is None) == (duration_max is None):
        raise DesignError("give a fixed duration or a duration_max (a free final time), one of the two")
    for name, v in (("duration", duration), ("duration_max", duration_max)):
        if v is not None and not (math.isfinite(v) and 0 < v <= 1e4):
            raise DesignError(f"{name} = {v!r}: expected seconds in (0, 10000]")
    if max_time is not None and not (math.isfinite(max_time) and 0 < max_time <= 1e6):
        raise DesignError(f"max_time = {max_time!r}: expected seconds in (0, 1000000], or None")
    if minimize == "time" and duration is not None:
        raise DesignError("minimize time needs a free final time: give duration_max, not duration")
    n, m = system.n_states, system.n_inputs
    if m == 0:
        raise DesignError(f"{system.key} has no input: there is no motion to plan")
    start = np.asarray(start, dtype=float).reshape(n)
    goal = np.asarray(goal, dtype=float).reshape(n)
    N = knots
    lo = np.array([float(system.params[f"{i}_min"]) for i in system.input_names])
    hi = np.array([float(system.params[f"{i}_max"]) for i in system.input_names])
    xg, ug, t_guess = _initial_guess(system, guess, start=start, goal=goal, N=N, seed=seed,
                                     duration=duration, duration_max=duration_max, lo=lo, hi=hi)
    for label, costs, names in (("state_cost", state_cost, system.state_names),
                                ("input_rate_cost", input_rate_cost, system.input_names)):
        for name, weight in (costs or {}).items():
            if name not in names:
                raise DesignError(f"{label} names {name!r}: expected one of {system.key}'s "
                                  f"({', '.join(names)})")
            if not (isinstance(weight, int | float) and math.isfinite(weight) and weight >= 0):
                raise DesignError(f"{label}[{name!r}] = {weight!r}: expected a non-negative "
                                  "number")
    problem = _problem(system, N, duration, duration_max, minimize, bounds or {}, lo, hi,
                       state_cost, input_rate_cost)
    f, opti, X, U, Um, T = problem.f, problem.opti, problem.X, problem.U, problem.Um, problem.T
    with problem.lock:
        opti.set_value(problem.start, start)
        opti.set_value(problem.goal, goal)
        opti.set_initial(X, xg.T)
        opti.set_initial(U, ug.T)
        opti.set_initial(Um, 0.5 * (ug[:-1] + ug[1:]).T)
        if duration is None:
            opti.set_initial(T, t_guess)
        t0 = time.process_time()
        value, stats, converged, status = _solve(problem, max_iterations=max_iterations,
                                                 max_time=max_time)
        solve_time = time.process_time() - t0
        Tv = float(value(T)) if duration is None else float(duration)
        xs = np.asarray(value(X), dtype=float).T.reshape(N + 1, n)
        us = np.asarray(value(U), dtype=float).T.reshape(N + 1, m)
        ums = np.asarray(value(Um), dtype=float).T.reshape(N, m)
        cost = float(value(opti.f))
    # The ends exactly where they were asked: the defects below measure the plan so pinned.
    xs[0], xs[-1] = start, goal
    defect = _max_defect(f, xs, us, ums, Tv / N, start, goal)
    return Trajectory(
        system=system.key, params=dict(system.params), state_names=system.state_names,
        input_names=system.input_names, times=np.linspace(0.0, Tv, N + 1), states=xs,
        inputs=us, mid_inputs=ums, converged=converged and defect < 1e-6,
        cost=cost, max_defect=defect, solve_time=solve_time,
        iterations=int(stats.get("iter_count", 0)), solver="ipopt (CasADi, exact Hessian)",
        settings={"knots": N, "minimize": minimize,
                  "guess": guess if isinstance(guess, str) else "file", "seed": seed,
                  "duration": duration, "duration_max": duration_max,
                  "bounds": {k: list(v) for k, v in (bounds or {}).items()},
                  **({"state_cost": {k: float(v) for k, v in state_cost.items()}}
                     if state_cost else {}),
                  **({"input_rate_cost": {k: float(v) for k, v in input_rate_cost.items()}}
                     if input_rate_cost else {}),
                  "start": start.tolist(), "goal": goal.tolist()},
        system_digest=system.digest, status=status,
    )


def check_guess(guess: Trajectory, *, n: int, m: int, duration_max: float | None,
                what: str = "the guess", bound: str = "duration_max") -> None:
    """Refuse a trajectory as a guess (:class:`DesignError`, one line that begins with
    *what*) unless it has *n* states and *m* inputs, finite values, strictly increasing
    finite times and, for a free final time, a duration within the final time's range
    ``[0.05 duration_max, duration_max]`` (*bound* names ``duration_max`` there)."""
    times = np.asarray(guess.times, dtype=float)
    if (np.shape(guess.states) != (times.size, n) or np.shape(guess.inputs) != (times.size, m)
            or np.shape(guess.mid_inputs) != (times.size - 1, m)):
        raise DesignError(f"{what}: its arrays are not those of a plan of {n} states and "
                          f"{m} inputs")
    if (times.size < 2 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0)
            or not all(np.all(np.isfinite(a)) for a in (guess.states, guess.inputs,
                                                         guess.mid_inputs))):
        raise DesignError(f"{what}: expected finite values at strictly increasing finite times")
    d = float(times[-1] - times[0])
    if duration_max is not None and not (0.05 * duration_max <= d <= duration_max):
        raise DesignError(f"{what}: its duration {d:.6g} s is outside the free final time's "
                          f"range [{0.05 * duration_max:g}, {duration_max:g}] s ({bound} "
                          f"{duration_max:g}): expected a plan of a duration within it")


def _initial_guess(system: System, guess: str | Trajectory, *, start: np.ndarray,
                   goal: np.ndarray, N: int, seed: int, duration: float | None,
                   duration_max: float | None, lo: np.ndarray,
                   hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The initial guess's states, inputs at the knots and final time."""
    n, m = system.n_states, system.n_inputs
    t_max = duration if duration is not None else duration_max  # one of the two is given
    assert t_max is not None
    t_guess = t_max if duration is not None else 0.5 * t_max
    s = np.linspace(0.0, 1.0, N + 1)
    if isinstance(guess, Trajectory):
        check_guess(guess, n=n, m=m, duration_max=duration_max)
        tt = s * guess.duration
        xg = np.column_stack([np.interp(tt, guess.times - guess.times[0], guess.states[:, i])
                              for i in range(n)])
        ug = guess.input_at(tt + guess.times[0]).reshape(N + 1, m)
        t_guess = guess.duration if duration is None else duration
    elif guess == "straight":
        xg = start + s[:, None] * (goal - start)
        ug = np.zeros((N + 1, m))
    elif guess == "random":
        rng = np.random.default_rng(seed)
        xg = start + s[:, None] * (goal - start)
        spread = np.array([float(system.spec.design_scales.get(nm, 1.0)) for nm in system.state_names])
        xg = xg + rng.normal(0.0, 1.0, xg.shape) * spread
        xg[0], xg[-1] = start, goal
        ug = rng.uniform(lo, hi, (N + 1, m))
    else:
        raise DesignError(f"guess = {guess!r}: expected random, straight or a trajectory file")
    return xg, ug, t_guess


def _stopper(problem: _Problem) -> Any:
    """IPOPT's iteration callback for *problem*: it stops the solve (returns 1) once a
    signal was noted in its ``signals``, an interrupt was recorded
    (:mod:`equilibrist.interrupt`) or its ``deadline`` (``time.monotonic``) has passed,
    saying which in its ``reason`` (``"interrupt"``, ``"time"``)."""
    ca = require_casadi()
    from equilibrist import interrupt

    nx, ng, npar = int(problem.opti.nx), int(problem.opti.ng), int(problem.opti.np)
    callback: Any = ca.Callback

    class Stopper(callback):  # type: ignore[misc]  # CasADi ships no types
        def __init__(self) -> None:
            ca.Callback.__init__(self)
            self.signals: list[int] = []
            self.deadline = math.inf
            self.reason = ""
            self.construct("equilibrist_stop", {})

        def get_n_in(self) -> int:
            return int(ca.nlpsol_n_out())

        def get_n_out(self) -> int:
            return 1

        def get_name_in(self, i: int) -> str:
            return str(ca.nlpsol_out(i))

        def get_name_out(self, i: int) -> str:
            return "stop"

        def get_sparsity_in(self, i: int) -> Any:
            size = {"f": 1, "x": nx, "lam_x": nx, "g": ng, "lam_g": ng}.get(ca.nlpsol_out(i), npar)
            return ca.Sparsity.dense(size, 1)

        def eval(self, arg: object) -> list[int]:
            if self.signals or interrupt.requested():
                self.reason = "interrupt"
            elif time.monotonic() >= self.deadline:
                self.reason = "time"
            return [1 if self.reason else 0]

    return Stopper()


@contextlib.contextmanager
def _signals_noted(noted: list[int]) -> Iterator[None]:
    """Within the block, Ctrl-C and SIGTERM are only noted in *noted* (a signal handler
    that raises inside IPOPT's callbacks would end the solve as a failure, with CasADi's
    warning); after it, the handlers are restored and the first signal noted is raised
    again (:func:`signal.raise_signal`), so that it acts as if it came then. Only the
    main thread handles signals: elsewhere this does nothing. A signal the process
    ignores stays ignored."""
    import signal

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    previous = {s: h for s, h in previous.items() if h not in (None, signal.SIG_IGN)}

    def note(signum: int, _frame: object) -> None:
        noted.append(signum)

    for s in previous:
        signal.signal(s, note)
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
        if noted:
            signal.raise_signal(noted[0])


def _solve(problem: _Problem, *, max_iterations: int,
           max_time: float | None) -> tuple[Any, Mapping[str, Any], bool, str]:
    """Solve *problem* from its guess: the values' reader, IPOPT's statistics, its success
    and its return status (:data:`TIMED_OUT` where *max_time* stopped it). An interrupt
    stops IPOPT at its next iteration and is raised."""
    opti = problem.opti
    if problem.stopper is None:
        problem.stopper = _stopper(problem)
    if problem.max_iterations != int(max_iterations):
        opti.solver("ipopt", {**IPOPT_OPTIONS, "iteration_callback": problem.stopper},
                    {**IPOPT_SETTINGS, "max_iter": int(max_iterations)})
        problem.max_iterations = int(max_iterations)
    stop = problem.stopper
    stop.signals, stop.reason = [], ""
    stop.deadline = math.inf if max_time is None else time.monotonic() + max_time
    with _signals_noted(stop.signals):
        try:
            sol = opti.solve()
            stats, value, converged = sol.stats(), sol.value, bool(sol.stats().get("success"))
        except RuntimeError:  # not converged: the debug values are the last iterate
            stats, value, converged = opti.stats(), opti.debug.value, False
    if stop.reason == "interrupt" and not stop.signals:
        raise KeyboardInterrupt  # recorded by the command line's handlers before the solve
    status = TIMED_OUT if stop.reason == "time" else str(stats.get("return_status", ""))
    return value, stats, converged, status


def _max_defect(f: Any, xs: np.ndarray, us: np.ndarray, ums: np.ndarray, h: float,
                start: np.ndarray, goal: np.ndarray) -> float:
    """The largest collocation defect (absolute), and the boundary conditions'."""
    fk = np.array([np.asarray(f(xs[k], us[k])).reshape(-1) for k in range(len(xs))])
    xm = 0.5 * (xs[:-1] + xs[1:]) + (h / 8) * (fk[:-1] - fk[1:])
    fm = np.array([np.asarray(f(xm[k], ums[k])).reshape(-1) for k in range(len(xm))])
    d = xs[1:] - xs[:-1] - (h / 6) * (fk[:-1] + 4 * fm + fk[1:])
    return float(max(np.max(np.abs(d)), np.max(np.abs(xs[0] - start)), np.max(np.abs(xs[-1] - goal))))
