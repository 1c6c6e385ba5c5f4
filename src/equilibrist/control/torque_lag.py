"""The motor's lag in the time-varying LQR (``--design-torque-response``).

A rig's motor does not give the commanded torque at once: per control period the torque
that acts is ``tau_k = tau_k-1 + k (u_k - tau_k-1)`` (:class:`~equilibrist.sim.rig.Rig`'s
``torque_response``, or a first-order lag of time constant ``tc`` sampled exactly,
``k = 1 - exp(-T / tc)``), limited to the input's range. A tracker that knows ``k``
compensates it:

* **the plan's torque led by the lag's inverse**: the command that makes the plan's torque
  act at sample ``k``, from the plan's torque of the sample before (the operating point's
  input before the first), ``u_k = tau_plan,k-1 + (tau_plan,k - tau_plan,k-1) / k``;
* **the gains of the model augmented with the torque state** ``tau_k-1``,

      [dx_k+1 ]   [A_k  (1 - k) B_k] [dx_k    ]   [k B_k]
      [dtau_k ] = [0    (1 - k) I  ] [dtau_k-1] + [k I  ] du_k,

  the same cost on ``dx`` and ``du`` (the torque state weighed by zero), the finite-horizon
  recursion from the balancing LQR of the augmented model at the operating point (its
  Riccati equation's stabilizing solution), so the gain on the plant's state and the gain on
  the torque state hand over together;
* **the torque state from the controller's own commands**: its state keeps ``tau``, run
  through the same response from the commands it sent (saturated), from the operating
  point's input, as the motor runs it.

The catch region is the augmented balance's on the plant's state (its Riccati solution's
block). The block of the tracker's parameters (:data:`LAYOUT`) sits after the tracker's
own, and the torque state after its state: the tracker's layout and source are unchanged.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import fixed
from equilibrist.control.discretize import discrete_matrices
from equilibrist.errors import ControllerError
from equilibrist.native.linear_layout import Layout

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

#: The lag's block: its ``k`` and the input limits the motor's torque keeps, the balance's
#: gain on the torque state, and the plan's (per sample). (No block may be named ``end``:
#: :meth:`~equilibrist.native.linear_layout.Layout.offsets` gives the vector's end by that key.)
LAYOUT = Layout("LG", ("kappa", "m", "steps"), (("limits", ("m", 2)), ("balance", ("m", "m")),
                                                 ("gains", ("steps", "m", "m"))))

#: The largest ``k`` designed for: at 2 the torque's own mode ``1 - k`` no longer decays.
K_MAX = 2.0


def response_k(value: object, rate: float) -> float:
    """The per-period ``k`` of ``--design-torque-response``: a number in ``(0, 2)`` is ``k``
    itself; a time (``20ms``, ``0.02s``) is a first-order lag's time constant, sampled
    exactly at *rate*, ``k = 1 - exp(-T / tc)``."""
    text = str(value).strip()
    unit = 1e-3 if text.endswith("ms") else 1.0 if text.endswith("s") else None
    try:
        number = float(text[:-2] if unit == 1e-3 else text[:-1] if unit == 1.0 else text)
    except ValueError:
        number = math.nan
    if unit is not None:
        tc = number * unit
        if not (math.isfinite(tc) and tc > 0.0):
            raise ControllerError(f"--design-torque-response {text!r}: expected a time "
                                  "constant > 0 (20ms, 0.02s) or a k in (0, 2)")
        return 1.0 - math.exp(-1.0 / (rate * tc))
    if not (math.isfinite(number) and 0.0 < number < K_MAX):
        raise ControllerError(f"--design-torque-response {text!r}: expected a k in (0, 2) or "
                              "a time constant (20ms, 0.02s)")
    return number


def augmented(Ad: np.ndarray, Bd: np.ndarray, kappa: float) -> tuple[np.ndarray, np.ndarray]:
    """The sampled model ``(Ad, Bd)`` with the torque state ``tau_k-1`` after its state."""
    n, m = Bd.shape
    A = np.zeros((n + m, n + m))
    A[:n, :n] = Ad
    A[:n, n:] = (1.0 - kappa) * Bd
    A[n:, n:] = (1.0 - kappa) * np.eye(m)
    B = np.vstack([kappa * Bd, kappa * np.eye(m)])
    return A, B


def _weights(Q: np.ndarray, m: int) -> np.ndarray:
    n = Q.shape[0]
    out = np.zeros((n + m, n + m))
    out[:n, :n] = Q
    return out


def balance(system: System, x_op: np.ndarray, u_op: np.ndarray, *, rate: float,
            Q: np.ndarray, R: np.ndarray, kappa: float) -> tuple[np.ndarray, np.ndarray]:
    """``(K, S)`` of the balancing LQR of the augmented model at the operating point:
    ``K`` is ``(m, n + m)``, ``S`` ``(n + m, n + m)``."""
    Ad, Bd = discrete_matrices(*system.jacobians(x_op, u_op), 1.0 / rate)
    A, B = augmented(Ad, Bd, kappa)
    S = fixed.symmetric(fixed.dare(A, B, _weights(Q, Bd.shape[1]), R))
    K = fixed.solve(R + fixed.mm(B.T, S, B), fixed.mm(B.T, S, A))
    if not (np.all(np.isfinite(S)) and np.all(np.isfinite(K))):
        raise ControllerError(f"the balancing LQR for a torque response k = {kappa:g} did not "
                              "converge")
    return K, S


def gains(system: System, xs: np.ndarray, us: np.ndarray, *, rate: float, Q: np.ndarray,
          R: np.ndarray, kappa: float, S_end: np.ndarray) -> np.ndarray:
    """The augmented model's time-varying gains ``(steps, m, n + m)`` along the plan's samples
    *xs*, *us* (the torque that acts), backward from *S_end*."""
    steps, m = xs.shape[0] - 1, us.shape[1]
    Qa = _weights(Q, m)
    S = np.array(S_end, dtype=float)
    out = np.zeros((steps, m, xs.shape[1] + m))
    for k in range(steps - 1, -1, -1):
        A, B = augmented(*discrete_matrices(*system.jacobians(xs[k], us[k]), 1.0 / rate), kappa)
        Kk = fixed.solve(R + fixed.mm(B.T, S, B), fixed.mm(B.T, S, A))
        S = fixed.symmetric(Qa + fixed.mm(A.T, S, A - fixed.matmul(B, Kk)))
        out[k] = Kk
    if not np.all(np.isfinite(out)):
        raise ControllerError("the time-varying LQR's Riccati recursion with the torque state did "
                              "not stay finite along the trajectory")
    return out


def block(system: System, *, kappa: float, end: np.ndarray, tau_gains: np.ndarray) -> np.ndarray:
    """The lag's parameters (:data:`LAYOUT`): *end* the balance's gain on the torque state
    ``(m, m)``, *tau_gains* the plan's ``(steps, m, m)``."""
    low, high = system.input_limits
    limits = np.column_stack([low, high])
    return LAYOUT.pack({"kappa": kappa, "m": system.n_inputs, "steps": tau_gains.shape[0]},
                       {"limits": limits, "balance": end, "gains": tau_gains})


def start(system: System, u_op: np.ndarray) -> np.ndarray:
    """The torque state at the start: the operating point's input within its limits (where
    the motor's torque starts)."""
    low, high = system.input_limits
    held: np.ndarray = np.minimum(np.maximum(np.asarray(u_op, dtype=float), low), high)
    return held


def source(*, n: int, m: int, tail: int) -> str:
    """The source of ``lg_torque(i, t, z, y, params)`` (what the lag adds to input ``i``'s
    command: the plan's lead and the torque state's feedback) and ``lg_update`` (the torque
    state's step), for a tracker of *n* states and *m* inputs whose parameters end with
    *tail* values after the lag's block (another block's); the torque state is the last *m*
    entries of ``z``. It calls the tracker's ``tv_sample``, ``tv_at`` and
    ``tvlqr_caught``."""
    return LAYOUT.source() + f'''LG_TAIL = {tail}
LG_N = {n}


def lg_base(params):
    m = tv_at(params, TV_M)
    steps = tv_at(params, TV_STEPS)
    size = {len(LAYOUT.header)} + 2 * m + m * m + steps * m * m
    return int(params.shape[0]) - LG_TAIL - size


def lg_torque(i, t, z, y, params):
    """Input i's lead of the plan's torque by the lag's inverse, less the gain on the torque
    state's deviation from the torque that should have acted the period before."""
    o = lg_base(params)
    m = tv_at(params, TV_M)
    kappa = params[o + LG_KAPPA]
    nz = int(z.shape[0])
    k = tv_sample(t, params)
    lead = 0.0
    if tvlqr_caught(t, z, y, params) < 0.5:
        ou = tv_at(params, TV_O_US)
        now = params[ou + k * m + i]
        before = params[tv_at(params, TV_O_U_OP) + i]
        if k > 0:
            before = params[ou + (k - 1) * m + i]
        lead = (now - before) * (1.0 / kappa - 1.0)
        og = o + int(params[o + LG_O_GAINS]) + k * m * m
        acc = 0.0
        for j in range(m):
            prev = params[tv_at(params, TV_O_U_OP) + j]
            if k > 0:
                prev = params[ou + (k - 1) * m + j]
            acc += params[og + i * m + j] * (z[nz - m + j] - prev)
        return lead - acc
    oe = o + int(params[o + LG_O_BALANCE])
    acc = 0.0
    for j in range(m):
        acc += params[oe + i * m + j] * (z[nz - m + j] - params[tv_at(params, TV_O_U_OP) + j])
    return -acc


def lg_update(t, z, u_applied, params, z_out):
    """The torque state's step: the motor's response to the command sent, within its limits."""
    o = lg_base(params)
    m = tv_at(params, TV_M)
    kappa = params[o + LG_KAPPA]
    nz = int(z.shape[0])
    ol = o + int(params[o + LG_O_LIMITS])
    for j in range(m):
        tau = z[nz - m + j] + kappa * (u_applied[j] - z[nz - m + j])
        if tau < params[ol + 2 * j]:
            tau = params[ol + 2 * j]
        if tau > params[ol + 2 * j + 1]:
            tau = params[ol + 2 * j + 1]
        z_out[nz - m + j] = tau
'''
