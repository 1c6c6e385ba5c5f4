"""From continuous to discrete time: plant matrices and noise covariances.

Two methods, named:

``"zoh"`` (default)
    Exact for an input held constant over each period:
    ``[[Ad, Bd], [0, I]] = expm([[A, B], [0, 0]] T)``.
``"euler"``
    The seed's forward Euler step (seeds/002, "Discrete Kalman filter"):
    ``Ad = I + A T``, ``Bd = B T``.

Noise (SYSTEMS.md, "Control and estimation"): white process noise of
intensity ``QN`` entering through ``G`` becomes, over one period,
``Qd = int_0^T e^{A t} G QN G' e^{A' t} dt`` (computed by Van Loan's
method; with ``"euler"`` its first-order term ``G QN G' T``, consistent with
the Euler transition), and measurement noise of intensity ``RN`` averaged
over a period becomes ``Rd = RN / T``.
"""

from __future__ import annotations

import math

import numpy as np

from equilibrist.control import checks, fixed
from equilibrist.errors import DesignError
from equilibrist.numeric.linear import LinearModel

METHODS = ("zoh", "euler")


def _method(method: str) -> str:
    if method not in METHODS:
        raise DesignError(
            f"discretization method {method!r} is unknown: expected one of {', '.join(METHODS)}"
        )
    return method


def discrete_matrices(
    A: np.ndarray, B: np.ndarray, dt: float, *, method: str = "zoh"
) -> tuple[np.ndarray, np.ndarray]:
    """``(Ad, Bd)`` of ``x_dot = A x + B u`` sampled every *dt* seconds (the exponential in
    a fixed order of operations: :func:`equilibrist.control.fixed.expm`)."""
    _method(method)
    T = checks.positive_period(dt)
    Am = checks.square(A, "A")
    n = Am.shape[0]
    Bm = checks.with_rows(B, "B", n, "one per state")
    m = Bm.shape[1]
    if method == "euler":
        return np.eye(n) + Am * T, Bm * T
    block = np.zeros((n + m, n + m))
    block[:n, :n] = Am * T
    block[:n, n:] = Bm * T
    E = fixed.expm(block)
    return E[:n, :n], E[:n, n:]


def discretize(model: LinearModel, dt: float, *, method: str = "zoh") -> LinearModel:
    """The discrete-time model of a continuous :class:`LinearModel`.

    Parameters
    ----------
    model:
        A continuous model (``model.dt is None``).
    dt:
        Sample period [s], positive.
    method:
        ``"zoh"`` (exact for a held input) or ``"euler"`` (``I + A dt``, ``B dt``).

    Returns
    -------
    LinearModel
        ``Ad, Bd`` with the same ``C, D``, names and operating point, and
        ``dt`` set.

    Raises
    ------
    DesignError
        A model that is already discrete, a period that is not positive, an
        unknown method.
    """
    if model.dt is not None:
        raise DesignError(f"the model is already discrete (dt = {model.dt:g} s)")
    Ad, Bd = discrete_matrices(model.A, model.B, dt, method=method)
    return LinearModel(
        A=Ad,
        B=Bd,
        C=model.C,
        D=model.D,
        state_names=model.state_names,
        input_names=model.input_names,
        output_names=model.output_names,
        x0=model.x0,
        u0=model.u0,
        residual=model.residual,
        system=model.system,
        params=model.params,
        dt=float(dt),
        state_units=model.state_units,
        input_units=model.input_units,
    )


def van_loan(A: object, W: object, dt: float) -> np.ndarray:
    """``int_0^T e^{A t} W e^{A' t} dt`` by Van Loan's method.

    ``expm([[-A, W], [0, A']] T) = [[., F^-1 Qd], [0, F']]`` with
    ``F = e^{A T}``, so ``Qd = F (F^-1 Qd)``.

    Parameters
    ----------
    A:
        ``n x n`` continuous state matrix.
    W:
        ``n x n`` noise intensity as seen by the state, ``G QN G'``.
    dt:
        Period ``T`` [s].
    """
    return sampled_noise(A, W, dt)[1]


def sampled_noise(A: object, W: object, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(F, Qd)``: ``F = e^{A T}`` and Van Loan's ``Qd`` (:func:`van_loan`), both from the
    one exponential."""
    T = checks.positive_period(dt)
    Am = checks.square(A, "A")
    n = Am.shape[0]
    Wm = checks.matrix(W, "G QN G'", (n, n), "one row and column per state")
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n] = -Am * T
    block[:n, n:] = Wm * T
    block[n:, n:] = Am.T * T
    E = fixed.expm(block)
    F = E[n:, n:].T
    return F, checks.symmetric(fixed.matmul(F, E[:n, n:]))


def discrete_noise(
    A: object,
    G: object,
    QN: object,
    RN: object,
    dt: float,
    *,
    method: str = "zoh",
) -> tuple[np.ndarray, np.ndarray]:
    """``(Qd, Rd)``: per-sample covariances of continuous white noises.

    ``Qd`` is Van Loan's integral for ``"zoh"`` and ``G QN G' T`` for
    ``"euler"``; ``Rd = RN / T`` for both.
    """
    _method(method)
    T = checks.positive_period(dt)
    Am = checks.square(A, "A")
    n = Am.shape[0]
    Gm = checks.with_rows(G, "G", n, "one per state")
    k = Gm.shape[1]
    QNm = checks.matrix(QN, "QN", (k, k), f"one row and column per noise input, {k} of them")
    RNm = checks.square(RN, "RN")
    W = checks.symmetric(fixed.mm(Gm, QNm, Gm.T))
    Qd = W * T if method == "euler" else van_loan(Am, W, T)
    return Qd, RNm / T


def delay_state_names(input_names: tuple[str, ...], periods: int) -> tuple[str, ...]:
    """The names of the commands in flight of a model delayed by *periods* samples, oldest
    first: ``F_sent2, F_sent1`` is the command sent two periods ago, then the one sent one
    period ago (:func:`with_input_delay`'s states after the plant's)."""
    return tuple(f"{name}_sent{age}" for age in range(periods, 0, -1) for name in input_names)


def with_input_delay(model: LinearModel, periods: int) -> LinearModel:
    """The discrete *model* whose input acts *periods* samples after it is sent, as a model
    without delay: the state extended by the commands sent but not yet acted.

    ``x_{k+1} = Ad x_k + Bd u_{k-N}`` becomes, with ``xi_k = [x_k; u_{k-N}; ...; u_{k-1}]``::

        xi_{k+1} = [[Ad, Bd, 0, ..., 0],      xi_k + [0; ...; 0; I] u_k
                    [0,  0,  I, ..., 0],
                    ...
                    [0,  0,  0, ..., I],
                    [0,  0,  0, ..., 0]]
        y_k      = [C, 0, ..., 0] xi_k

    The measurements are the plant's (``D = 0``: a delayed input reaches no output at
    once). A measurement *N* samples late (``y_k = C x_{k-N}`` with ``x_{k+1} = Ad x_k +
    Bd u_k``) is the same model for ``x_{k-N}``: the two delays are one shift of the loop.
    The operating point of each command in flight is the plant's input ``u0``; the states
    after the plant's are named by :func:`delay_state_names`. ``periods = 0`` returns
    *model* itself.

    Raises
    ------
    DesignError
        A continuous model, a model whose measurements depend on its input, or *periods*
        not a whole number >= 0.
    """
    if isinstance(periods, bool) or not isinstance(periods, int | np.integer) or periods < 0:
        raise DesignError(f"delay = {periods!r}: expected a whole number of periods >= 0")
    if model.dt is None:
        raise DesignError("a delay in samples needs a discrete model (a sample period)")
    if periods == 0:
        return model
    if np.any(np.asarray(model.D) != 0):
        raise DesignError(
            "a delayed input cannot reach a measurement at once: the model's D must be zero"
        )
    n, m, p = model.n_states, model.n_inputs, model.n_outputs
    size = n + int(periods) * m
    A = np.zeros((size, size))
    A[:n, :n] = model.A
    A[:n, n : n + m] = model.B
    A[n : size - m, n + m :] = np.eye(size - n - m)
    B = np.zeros((size, m))
    B[size - m :, :] = np.eye(m)
    C = np.zeros((p, size))
    C[:, :n] = model.C
    units = model.input_units * int(periods) if model.input_units else ()
    return LinearModel(
        A=A,
        B=B,
        C=C,
        D=np.zeros((p, m)),
        state_names=model.state_names + delay_state_names(model.input_names, int(periods)),
        input_names=model.input_names,
        output_names=model.output_names,
        x0=np.concatenate([model.x0, np.tile(model.u0, int(periods))]),
        u0=model.u0,
        residual=model.residual,
        system=model.system,
        params=model.params,
        dt=model.dt,
        state_units=model.state_units + units if model.state_units and units else (),
        input_units=model.input_units,
    )


def velocity_filter_gain(cutoff: float, rate: float) -> float:
    """The rig's velocity filter's gain per period, ``a = 1 - exp(-2 pi f_c T)`` for the
    cutoff *cutoff* [Hz] at *rate* [Hz], computed as :meth:`equilibrist.sim.rig.Rig.pack`
    computes it (the same bits): its filter is ``v_f += a (v - v_f)``."""
    return -math.expm1(-2.0 * math.pi * float(cutoff) / float(rate))


def filter_state_names(outputs: tuple[str, ...]) -> tuple[str, ...]:
    """The states :func:`with_velocity_filter` adds: each filtered output's reading,
    ``theta1_dot_filtered``."""
    return tuple(f"{name}_filtered" for name in outputs)


def with_velocity_filter(model: LinearModel, outputs: tuple[str, ...], gain: float) -> LinearModel:
    """The discrete *model* whose measured *outputs* are read through the rig's first-order
    low-pass ``f_k = f_{k-1} + a (v_k - f_{k-1})`` (``a`` = *gain*,
    :func:`velocity_filter_gain`; ``v_k = Cv x_k`` the output as the model measures it), as
    a model without the filter: the state extended by the filtered readings ``f_k``, which
    the filtered outputs then measure::

        [x; f]_{k+1} = [[Ad, 0], [a Cv Ad, (1 - a) I]] [x; f]_k + [Bd; a Cv Bd] u_k
        y_k = f_k (a filtered output),  C x_k (any other)

    (``f_{k+1} = (1 - a) f_k + a Cv x_{k+1}``, ``x_{k+1} = Ad x_k + Bd u_k``). Each output
    still reads one state, as the Kalman filter's source needs. The operating point of each
    reading is its output's there. The model's measurements must not depend on its input
    (``D = 0``).

    Raises
    ------
    DesignError
        A continuous model, a ``D`` that is not zero, an output the model does not measure
        or one named twice, a gain outside ``(0, 1]``.
    """
    if model.dt is None:
        raise DesignError("a velocity filter of samples needs a discrete model (a sample period)")
    if np.any(np.asarray(model.D) != 0):
        raise DesignError("a filtered measurement cannot depend on the input at once: the "
                          "model's D must be zero")
    unknown = [o for o in outputs if o not in model.output_names]
    if unknown or len(set(outputs)) != len(outputs) or not outputs:
        raise DesignError(f"filtered outputs {', '.join(outputs) or '(none)'}: expected measured "
                          f"outputs, each once ({', '.join(model.output_names)})")
    if not (0.0 < gain <= 1.0):
        raise DesignError(f"velocity filter gain {gain!r}: expected a number in (0, 1]")
    n, m, p, nf = model.n_states, model.n_inputs, model.n_outputs, len(outputs)
    rows = [model.output_names.index(o) for o in outputs]
    Cv = np.asarray(model.C, dtype=float)[rows]
    A = np.zeros((n + nf, n + nf))
    A[:n, :n] = model.A
    A[n:, :n] = gain * fixed.matmul(Cv, model.A)
    A[n:, n:] = (1.0 - gain) * np.eye(nf)
    B = np.vstack([model.B, gain * fixed.matmul(Cv, model.B)])
    C = np.zeros((p, n + nf))
    C[:, :n] = model.C
    for i, row in enumerate(rows):
        C[row] = 0.0
        C[row, n + i] = 1.0
    units = tuple(model.state_units[list(model.state_names).index(o)] if o in model.state_names
                  else "" for o in outputs) if model.state_units else ()
    return LinearModel(
        A=A,
        B=B,
        C=C,
        D=np.zeros((p, m)),
        state_names=model.state_names + filter_state_names(outputs),
        input_names=model.input_names,
        output_names=model.output_names,
        x0=np.concatenate([model.x0, np.asarray(model.y0, dtype=float)[rows]]),
        u0=model.u0,
        residual=model.residual,
        system=model.system,
        params=model.params,
        dt=model.dt,
        state_units=model.state_units + units if units else (),
        input_units=model.input_units,
    )
