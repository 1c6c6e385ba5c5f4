"""The MPC running: :class:`MPCRuntime`, the MPC's C library (:mod:`equilibrist.native.mpc_library`:
DAQP and the generated driver, with the Kalman filter in front as the linear controller's
library) compiled once per cache folder and called through ctypes; used by :mod:`equilibrist.control.mpc`.

The simulated MPC is the C that ``export`` writes, to the bit: the same driver, the same
DAQP, the same filter, built with the same arithmetic flags (no contraction).
"""

from __future__ import annotations

import ctypes
import functools
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control.mpc_problem import STATUS

if TYPE_CHECKING:
    from equilibrist.control.mpc import MPC

_P = ctypes.c_void_p


class MPCRuntime:
    """The MPC running: ``reset``, ``output``, ``update`` (a PythonController).

    Also records ``solve_times`` (seconds per sample's call), ``last_status``,
    ``last_iterations`` (DAQP's, 0 for the LQR's exact move) and ``fallbacks``.
    *exact_unconstrained* (default): where the LQR's trajectory meets every constraint, its
    move is the QP's minimizer and is applied without a solve; ``False`` solves every QP.
    *iter_limit*: DAQP's cap on its iterations (default
    :data:`~equilibrist.native.daqp_library.ITER_LIMIT`). Each runtime loads its own copy of the library (its DAQP
    workspace is static data).
    """

    # The library's entries (ctypes functions; the filter's only with a Kalman filter).
    _setup: Any
    _step: Any
    _move: Any
    _iterations: Any
    _init: Any
    _output: Any
    _update: Any
    _estimate: Any

    def __init__(self, ctrl: MPC, *, exact_unconstrained: bool = True,
                 iter_limit: int | None = None) -> None:
        from equilibrist.native.build import private
        from equilibrist.native.mpc_library import compiled_library

        self.ctrl = ctrl
        self.exact_unconstrained = exact_unconstrained
        self.iter_limit = iter_limit
        self.rate: float | None = ctrl.rate
        self.outputs: tuple[str, ...] | None = ctrl.output_names
        self.estimate: np.ndarray | None = None
        self.solve_times: list[float] = []
        prob = ctrl.problem
        n, m, ny = prob.n, prob.m, len(ctrl.output_names)
        self._kalman = ctrl.estimator == "kalman"
        lib = private(compiled_library(ctrl, shortcut=exact_unconstrained,
                                       iter_limit=iter_limit))
        self._lib = lib
        entries = {"setup": 0, "step": 2, "move": 2, "iterations": 0}
        if self._kalman:
            entries.update(init=1, output=3, update=3, estimate=3)
        for name, count in entries.items():
            fn = lib[f"mpc_{name}"]
            fn.argtypes = [_P] * count
            fn.restype = None if name in ("init", "update", "estimate") else ctypes.c_int
            setattr(self, f"_{name}", fn)
        # The call's buffers, and their addresses (passed as integers: the cheapest call).
        self._x, self._y, self._ua = np.zeros(n), np.zeros(ny), np.zeros(m)
        self._du, self._u, self._xhat = np.zeros(m), np.zeros(m), np.zeros(n)
        self._z = np.zeros(n)  # the filter's state (the library's mpc_filter struct)
        self._p = {k: getattr(self, f"_{k}").ctypes.data
                   for k in ("x", "y", "ua", "du", "u", "xhat", "z")}
        self.reset()

    def __reduce__(self) -> tuple[functools.partial[MPCRuntime], tuple[MPC]]:
        # The library's workspace does not pickle: a copy sent to a batch's worker is a new
        # runtime of the same MPC, fresh as a run starts (the batch resets each run's
        # controller).
        return (functools.partial(MPCRuntime, exact_unconstrained=self.exact_unconstrained,
                                  iter_limit=self.iter_limit),
                (self.ctrl,))

    @property
    def z(self) -> np.ndarray:
        """The filter's state: the predicted deviation ``xhat_{k|k-1} - x_op`` (a copy)."""
        return self._z.copy()

    @z.setter
    def z(self, value: np.ndarray) -> None:
        self._z[:] = np.asarray(value, dtype=float)

    def reset(self) -> None:
        flag = int(self._setup())
        if flag != 0:
            from equilibrist.errors import ControllerError

            raise ControllerError(f"the MPC's DAQP setup failed (flag {flag})")
        if self._kalman:
            self._init(self._p["z"])
        self.estimate = None
        self.last_status = ""
        self.last_iterations = 0
        self.fallbacks = 0

    def _record(self, flag: int) -> None:
        self.last_iterations = int(self._iterations())
        if flag == 0:
            self.last_status = "unconstrained"
            return
        self.last_status = STATUS.get(flag) or f"exit flag {flag}"
        if flag < 0:
            self.fallbacks += 1  # no solution: the LQR inside the hard limits, a cold start next

    def lqr_feasible(self, dx0: np.ndarray) -> bool:
        """Whether the LQR's own trajectory from *dx0* meets every constraint over the horizon.

        Then it is the QP's minimizer (``v = 0``, the unconstrained minimizer
        of the quadratic part, with zero slack), and the controller applies
        it exactly instead of solving: ``z = 0`` within the bounds of
        :meth:`MPCProblem.qp_bounds` (one product with the precomputed
        predictions ``Fu`` and ``Fs``).
        """
        bu, bl = self.ctrl.problem.qp_bounds(np.asarray(dx0, dtype=float))
        rows = slice(self.ctrl.problem.n_variables, None)
        return bool(np.all(bl[rows] <= 0.0) and np.all(bu[rows] >= 0.0))

    def solve(self, dx0: np.ndarray) -> np.ndarray:
        """The first move ``du_0`` of the QP from the deviation *dx0*, inside the hard limits
        (the library's ``mpc_move``)."""
        self._x[:] = dx0
        t0 = time.perf_counter()
        flag = self._move(self._p["x"], self._p["du"])
        self.solve_times.append(time.perf_counter() - t0)
        self._record(flag)
        return self._du.copy()

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        p = self._p
        if self._kalman:
            self._y[:] = y
            t0 = time.perf_counter()
            flag = self._output(p["z"], p["y"], p["u"])
            self.solve_times.append(time.perf_counter() - t0)
            self._estimate(p["z"], p["y"], p["xhat"])
            self.estimate = self._xhat.copy()
        else:
            self._x[:] = y
            t0 = time.perf_counter()
            flag = self._step(p["x"], p["u"])
            self.solve_times.append(time.perf_counter() - t0)
            self.estimate = self._x.copy()
        self._record(flag)
        return self._u.copy()

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        if self._kalman:
            self._y[:] = y
            self._ua[:] = u_applied
            self._update(self._p["z"], self._p["y"], self._p["ua"])


__all__ = [
    "MPCRuntime",
]
