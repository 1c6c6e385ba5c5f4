"""Swing-up: bring a rig from hanging to upright, then balance it there.

The controller is two laws and a supervisor that chooses between them at
every sample:

*Energy pumping* (Astrom and Furuta 2000, "Swinging up a pendulum by energy
control", Automatica 36) for the cart-pole, the reaction-wheel pendulum and
the rotary (Furuta) pendulum. ``E`` is the pendulum's own energy measured
from upright (``E = 0`` upright at rest, ``E = -2 m g l`` hanging at rest):

* cart-pole: ``E = J theta_dot^2 / 2 + m_p g l (cos theta - 1)`` with
  ``J = I_p + m_p l^2``; the pendulum's energy changes at the rate
  ``-m_p l a theta_dot cos theta`` when the cart accelerates at ``a``, so
  the cart is asked for ``a = sat_amax(k_E (E - E0) sign(theta_dot cos theta))
  - k_x x - k_v x_dot``: the first term pumps, the last two keep the cart
  near the middle of its track (``|x| <= x_max``). The force is
  ``F = (m_c + m_p) a + b_c x_dot``.
* rotary pendulum: the same law on the pendulum's energy
  (``J = I_p + m_p l_p^2``), with the arm's torque in place of the cart's
  force (the arm's acceleration plays the cart's; ``a`` is a torque here,
  bounded by ``a_max``), and a light damping ``-k_v phi_dot`` of the arm.
* reaction wheel: the motor's torque acts on the pendulum directly
  (``-tau``), so ``dE/dt = -tau theta_dot`` and the law is
  ``tau = sat_amax(k_E (E - E0) sign(theta_dot))``
  (``J = I + m L^2 + m_w L_w^2``, the wheel's mass carried at ``L_w``).

For each of them the energy rises monotonically while the law is not
saturated by the actuator and its centering terms are small (``dE/dt =
-c k_E (E - E0) |theta_dot cos theta|`` with ``c > 0``); it stops rising
when ``E`` reaches ``E0`` (default 0: the upright's energy).

*Energy shaping on the collocated joint* for the acrobot (Xin and Kaneda,
"Analysis of the energy-based swing-up control of the Acrobot", Int. J.
Robust Nonlinear Control 17 (2007), on the partial feedback
linearization of Spong 1995, "The swing up control problem for the acrobot",
IEEE Control Systems 15). ``E`` is the total energy from upright, which
changes at the rate ``dE/dt = tau theta2_dot``. The elbow's torque is the one
that makes ``V = k_E (E - E0)^2 / 2 + k_D theta2_dot^2 / 2 + k_P theta2^2 / 2``
fall as ``dV/dt = -k_V theta2_dot^2``:
``tau = (-(k_V theta2_dot + k_P theta2) det M + k_D (M11 (h2 + g2) - M12 (h1
+ g1))) / (k_E (E - E0) det M + k_D M11)`` (``M`` the inertia matrix, ``h``
the velocity terms, ``g`` gravity's). The acrobot thus tends to the upright's
energy with the elbow straight and still: link 1 swinging as one rigid
pendulum on the homoclinic orbit, which comes to upright slowly and straight
through the balance's catch region. The denominator keeps its sign for
``k_D > k_E (E0 - E_hanging) max(det M / M11)`` (about 40 for the catalogue's
acrobot); the default ``k_D = 30`` lies below that bound, for a faster
start from hanging: at the hanging energy it holds while ``|theta2| < 1.4
rad``, and more widely as ``E`` rises; where the denominator passes through
zero the motor's limit bounds the command. (In trials on the catalogue's
acrobot, with Gymnasium's heavy links ``I1 = I2 = 1 kg m^2``, Spong's
own reference for the elbow, ``alpha atan(theta1_dot)`` under a stiff PD,
and a PD with an energy term left the energy oscillating below the
upright's: the two links traded it rather than gained it.)

*Supervisor.* The balancing controller is the design's discrete LQR
``u = u_op - K (x_hat - x_op)`` (Riccati solution ``S``). Its catch region
is the level set ``V = dx' S dx < c_in`` on which the LQR's command just
reaches the actuator limit, ``c_sat = min_j u_lim_j^2 / (K S^-1 K')_jj``
(inside it the linear closed loop neither saturates nor leaves the set);
``c_in = catch_fraction * c_sat``. It hands back to pumping when
``V > c_out = release_factor * c_in`` (hysteresis; 20 for the acrobot, whose
``S`` weighs the rates so heavily that the estimated rates' noise alone
lifts ``V`` above ``4 c_in`` now and then while it balances well inside
``c_in``). Angles are wrapped to
within half a turn of upright; coordinates whose value does not matter (the
reaction wheel's angle, the rotary pendulum's arm) are *free*: the balance
holds them where they were when it caught the pendulum.

*LQG hand-over* (``balance="lqg"``). The balance runs on the design's
discrete Kalman filter instead of the tracker: started at the catch from
the tracker's estimate (its state ``kz``, the predicted deviation from the
held reference, becomes ``Ad dx + Bd du`` of that sample), then
``dx = kz + M (dy - C kz)`` (``current`` form) or ``dx = kz`` with
``kz+ = Ad kz + Bd du + L (dy - C kz)`` (``predictor``), the contract's LQG
sums. The supervisor is the default's (``V`` on the tracker's estimate,
the same hysteresis): the filter only makes the balancing command, and it
starts afresh at every catch.

*Estimator.* The rigs measure angles and positions only. The controller
estimates the rates with a steady-state alpha-beta tracker per measured
coordinate (the Kalman filter of a constant-velocity model; gains from
Kalata's tracking index with the sensor's noise and an acceleration of
``accel`` as the model's process noise): it is valid along the whole swing,
where a filter linearized at upright is not.

All of it is written as plain functions of flat ``float64`` arrays
(:func:`swingup_output`, :func:`swingup_update`), which are translated to C
into the simulation core (:mod:`equilibrist.native.pyc`), and which the C
export writes line for line.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control.controller import (
    ControllerError,
    NonlinearController,
)

if TYPE_CHECKING:
    from equilibrist.control.design import Design
    from equilibrist.numeric.system import System

#: The systems a swing-up exists for, and the law each uses.
LAWS = {"cartpole": 0, "reaction_wheel_pendulum": 1, "furuta": 2, "acrobot": 3}
LAW_NAMES = ("cart", "wheel", "rotary", "acrobot")

# --- layout of the parameters ``cp`` and of the state ``z`` (one place: the source,
# the Python runtime and the C export read these) -----------------------------------
CP_SLOTS = ("law", "T", "ke", "amax", "e0", "kx", "kv", "kp", "c_in", "c_out", "alpha",
            "beta", "u_min", "u_max", "u_op", "kd", "lqg", "kform")
N_PHYS = 8
N_STATES = 4  # every rig with a swing-up has two coordinates
CP_BLOCKS = (("phys", N_PHYS), ("x_op", N_STATES), ("K", N_STATES), ("S", N_STATES * N_STATES),
             ("wrap", N_STATES), ("free", N_STATES), ("Ad", N_STATES * N_STATES),
             ("Bd", N_STATES), ("Kf", N_STATES * 2))
Z_SLOTS = (("init", 1), ("mode", 1), ("xhat", N_STATES), ("ref", N_STATES), ("kz", N_STATES))

#: The balancing controllers the supervisor can hand over to (``balance=``).
BALANCES = ("lqr", "lqg")

MODE_PUMP, MODE_BALANCE = 0.0, 1.0


def _offsets(slots: tuple[tuple[str, int], ...], start: int = 0) -> dict[str, int]:
    out, at = {}, start
    for name, size in slots:
        out[name] = at
        at += size
    out["end"] = at
    return out


CP = {**{name: i for i, name in enumerate(CP_SLOTS)},
      **_offsets(CP_BLOCKS, len(CP_SLOTS))}
Z = _offsets(Z_SLOTS)


def layout_constants() -> dict[str, int]:
    """The layout as the source's constants (``SU_KE = 2``, ``SU_Z_MODE = 1`` ...)."""
    out = {f"SU_{k.upper()}": v for k, v in CP.items() if k != "end"}
    out.update({f"SU_Z_{k.upper()}": v for k, v in Z.items() if k != "end"})
    return out


#: The law, in the Python the C translation knows: compiled into the simulation core as a
#: :class:`~equilibrist.control.controller.NonlinearController` and run as is
#: in Python. Written with scalars for the four states (no allocation).
LAW_SOURCE = """
def su_wrap(a):
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


def su_sign(v):
    if v > 0.0:
        return 1.0
    if v < 0.0:
        return -1.0
    return 0.0


def su_clip(v, lo, hi):
    if v < lo:
        return lo
    if v > hi:
        return hi
    return v


def su_energy(x0, x1, x2, x3, p):
    law = int(p[SU_LAW])
    ph = SU_PHYS
    if law == 3:
        m1 = p[ph]
        m2 = p[ph + 1]
        l1 = p[ph + 2]
        lc1 = p[ph + 3]
        lc2 = p[ph + 4]
        i1 = p[ph + 5]
        i2 = p[ph + 6]
        g = p[ph + 7]
        c2 = eq_cos(x1)
        d1 = m1 * lc1 * lc1 + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * c2) + i1 + i2
        d2 = m2 * (lc2 * lc2 + l1 * lc2 * c2) + i2
        d3 = m2 * lc2 * lc2 + i2
        kin = 0.5 * (d1 * x2 * x2 + 2.0 * d2 * x2 * x3 + d3 * x3 * x3)
        pot = -g * (m1 * lc1 * eq_cos(x0) + m2 * (l1 * eq_cos(x0) + lc2 * eq_cos(x0 + x1)))
        return kin + pot - g * (m1 * lc1 + m2 * (l1 + lc2))
    return 0.5 * p[ph] * x3 * x3 + p[ph + 1] * (eq_cos(x1) - 1.0)


def su_pump(x0, x1, x2, x3, p):
    law = int(p[SU_LAW])
    ph = SU_PHYS
    e = su_energy(x0, x1, x2, x3, p) - p[SU_E0]
    ke = p[SU_KE]
    amax = p[SU_AMAX]
    if law == 0:
        a = su_clip(ke * e * su_sign(x3 * eq_cos(x1)), -amax, amax)
        a = a - p[SU_KX] * x0 - p[SU_KV] * x2
        # The force that gives the cart the acceleration a exactly.
        mlc = p[ph + 4] * eq_cos(x1)
        th_dd = (p[ph + 1] * eq_sin(x1) - p[ph + 5] * x3 - mlc * a) / p[ph]
        return (p[ph + 2] * a + mlc * th_dd - p[ph + 4] * eq_sin(x1) * x3 * x3
                + p[ph + 3] * x2)
    if law == 1:
        return su_clip(ke * e * su_sign(x3), -amax, amax) - p[SU_KV] * (x2 - x3)
    if law == 2:
        return su_clip(ke * e * su_sign(x3 * eq_cos(x1)), -amax, amax) - p[SU_KV] * x2
    m1 = p[ph]
    m2 = p[ph + 1]
    l1 = p[ph + 2]
    lc1 = p[ph + 3]
    lc2 = p[ph + 4]
    i1 = p[ph + 5]
    i2 = p[ph + 6]
    g = p[ph + 7]
    t2 = su_wrap(x1)
    c2 = eq_cos(t2)
    s2 = eq_sin(t2)
    m11 = m1 * lc1 * lc1 + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * c2) + i1 + i2
    m12 = m2 * (lc2 * lc2 + l1 * lc2 * c2) + i2
    m22 = m2 * lc2 * lc2 + i2
    det = m11 * m22 - m12 * m12
    hg2 = m2 * l1 * lc2 * s2 * x2 * x2 + m2 * lc2 * g * eq_sin(x0 + t2)
    hg1 = (-m2 * l1 * lc2 * s2 * (2.0 * x2 * x3 + x3 * x3)
           + (m1 * lc1 + m2 * l1) * g * eq_sin(x0) + m2 * lc2 * g * eq_sin(x0 + t2))
    # Xin and Kaneda's energy law: V = ke (E - E0)^2 / 2 + kd x3^2 / 2 + kp t2^2 / 2
    # falls as dV/dt = -kv x3^2 (while the motor is not saturated).
    kd = p[SU_KD]
    num = -(p[SU_KV] * x3 + p[SU_KP] * t2) * det + kd * (m11 * hg2 - m12 * hg1)
    den = ke * e * det + kd * m11
    if den == 0.0:
        return 0.0
    return num / den


def su_xhat(z, y, p, i):
    # The alpha-beta tracker's current estimate of state i (positions 0, 1; rates 2, 3).
    if z[SU_Z_INIT] == 0.0:
        if i < 2:
            return y[i]
        return 0.0
    if i < 2:
        return z[SU_Z_XHAT + i] + p[SU_ALPHA] * (y[i] - z[SU_Z_XHAT + i])
    return z[SU_Z_XHAT + i] + p[SU_BETA] / p[SU_T] * (y[i - 2] - z[SU_Z_XHAT + i - 2])


def su_ref(z, xi, p, i, balancing):
    # The balance's reference of state i: held while balancing; a free
    # coordinate is caught where it is.
    if balancing:
        return z[SU_Z_REF + i]
    if p[SU_FREE + i] != 0.0:
        return xi
    return p[SU_X_OP + i]


def su_dev(xi, ri, p, i):
    d = xi - ri
    if p[SU_WRAP + i] != 0.0:
        d = su_wrap(d)
    return d


def su_level(d0, d1, d2, d3, p):
    s = SU_S
    v = 0.0
    v += d0 * (p[s] * d0 + p[s + 1] * d1 + p[s + 2] * d2 + p[s + 3] * d3)
    v += d1 * (p[s + 4] * d0 + p[s + 5] * d1 + p[s + 6] * d2 + p[s + 7] * d3)
    v += d2 * (p[s + 8] * d0 + p[s + 9] * d1 + p[s + 10] * d2 + p[s + 11] * d3)
    v += d3 * (p[s + 12] * d0 + p[s + 13] * d1 + p[s + 14] * d2 + p[s + 15] * d3)
    return v


def su_kest(z, y, p, i):
    # The Kalman filter's estimate (deviation from the held reference) of state i
    # while the LQG balances: current form kz + M (dy - C kz), predictor form kz.
    kz = SU_Z_KZ
    if p[SU_KFORM] != 0.0:
        return z[kz + i]
    m = SU_KF + 2 * i
    e0 = su_dev(y[0], z[SU_Z_REF], p, 0) - z[kz]
    e1 = su_dev(y[1], z[SU_Z_REF + 1], p, 1) - z[kz + 1]
    return z[kz + i] + p[m] * e0 + p[m + 1] * e1


def su_kpred(z, y, p, i, d0, d1, d2, d3, du, balancing):
    # The filter's prediction of state i for the next sample from this sample's
    # estimate d (at the hand-over: the tracker's), the predictor form's correction
    # once it runs.
    a = SU_AD + 4 * i
    v = p[a] * d0 + p[a + 1] * d1 + p[a + 2] * d2 + p[a + 3] * d3 + p[SU_BD + i] * du
    if balancing and p[SU_KFORM] != 0.0:
        kz = SU_Z_KZ
        m = SU_KF + 2 * i
        e0 = su_dev(y[0], z[SU_Z_REF], p, 0) - z[kz]
        e1 = su_dev(y[1], z[SU_Z_REF + 1], p, 1) - z[kz + 1]
        v = v + p[m] * e0 + p[m + 1] * e1
    return v


def su_mode(z, v, p):
    if z[SU_Z_MODE] == 1.0:
        if v <= p[SU_C_OUT]:
            return 1.0
        return 0.0
    if v < p[SU_C_IN]:
        return 1.0
    return 0.0


def output(t, z, y, r, p, u_out):
    x0 = su_xhat(z, y, p, 0)
    x1 = su_xhat(z, y, p, 1)
    x2 = su_xhat(z, y, p, 2)
    x3 = su_xhat(z, y, p, 3)
    bal = z[SU_Z_MODE] == 1.0
    d0 = su_dev(x0, su_ref(z, x0, p, 0, bal), p, 0)
    d1 = su_dev(x1, su_ref(z, x1, p, 1, bal), p, 1)
    d2 = su_dev(x2, su_ref(z, x2, p, 2, bal), p, 2)
    d3 = su_dev(x3, su_ref(z, x3, p, 3, bal), p, 3)
    mode = su_mode(z, su_level(d0, d1, d2, d3, p), p)
    if mode == 1.0 and bal and p[SU_LQG] != 0.0:
        d0 = su_kest(z, y, p, 0)
        d1 = su_kest(z, y, p, 1)
        d2 = su_kest(z, y, p, 2)
        d3 = su_kest(z, y, p, 3)
    if mode == 1.0:
        k = SU_K
        raw = p[SU_U_OP] - (p[k] * d0 + p[k + 1] * d1 + p[k + 2] * d2 + p[k + 3] * d3)
    else:
        raw = su_pump(x0, x1, x2, x3, p)
    u_out[0] = su_clip(raw, p[SU_U_MIN], p[SU_U_MAX])


def update(t, z, y, r, u_applied, p, z_out):
    x0 = su_xhat(z, y, p, 0)
    x1 = su_xhat(z, y, p, 1)
    x2 = su_xhat(z, y, p, 2)
    x3 = su_xhat(z, y, p, 3)
    bal = z[SU_Z_MODE] == 1.0
    r0 = su_ref(z, x0, p, 0, bal)
    r1 = su_ref(z, x1, p, 1, bal)
    r2 = su_ref(z, x2, p, 2, bal)
    r3 = su_ref(z, x3, p, 3, bal)
    d0 = su_dev(x0, r0, p, 0)
    d1 = su_dev(x1, r1, p, 1)
    d2 = su_dev(x2, r2, p, 2)
    d3 = su_dev(x3, r3, p, 3)
    lqg = p[SU_LQG] != 0.0
    mode = su_mode(z, su_level(d0, d1, d2, d3, p), p)
    if mode == 1.0 and bal and lqg:
        d0 = su_kest(z, y, p, 0)
        d1 = su_kest(z, y, p, 1)
        d2 = su_kest(z, y, p, 2)
        d3 = su_kest(z, y, p, 3)
    du = u_applied[0] - p[SU_U_OP]
    for i in range(4):
        if lqg and mode == 1.0:
            z_out[SU_Z_KZ + i] = su_kpred(z, y, p, i, d0, d1, d2, d3, du, bal)
        else:
            z_out[SU_Z_KZ + i] = 0.0
    z_out[SU_Z_INIT] = 1.0
    z_out[SU_Z_MODE] = mode
    z_out[SU_Z_REF] = r0
    z_out[SU_Z_REF + 1] = r1
    z_out[SU_Z_REF + 2] = r2
    z_out[SU_Z_REF + 3] = r3
    z_out[SU_Z_XHAT] = x0 + p[SU_T] * x2
    z_out[SU_Z_XHAT + 1] = x1 + p[SU_T] * x3
    z_out[SU_Z_XHAT + 2] = x2
    z_out[SU_Z_XHAT + 3] = x3


def estimate(t, z, y, r, p, x_out):
    if z[SU_Z_MODE] == 1.0 and p[SU_LQG] != 0.0:
        for i in range(4):
            x_out[i] = z[SU_Z_REF + i] + su_kest(z, y, p, i)
        return
    x_out[0] = su_xhat(z, y, p, 0)
    x_out[1] = su_xhat(z, y, p, 1)
    x_out[2] = su_xhat(z, y, p, 2)
    x_out[3] = su_xhat(z, y, p, 3)
"""


def controller_source() -> str:
    """:data:`LAW_SOURCE` with the layout's constants in front."""
    head = "\n".join(f"{k} = {v}" for k, v in layout_constants().items())
    return head + "\n" + LAW_SOURCE


def python_namespace(*, compiled: bool = False) -> Any:
    """The source's functions, as plain Python (or compiled to C, as the simulation core
    runs them, when *compiled*: then only ``output``, ``update`` and ``estimate``)."""
    if compiled:
        from equilibrist.native.ctrl import controller_functions

        return controller_functions(controller_source(), ("output", "update", "estimate"))
    key = "python"
    if key not in _NAMESPACES:
        from equilibrist.control.controller import contract_namespace

        ns = contract_namespace()
        exec(compile(controller_source(), "<equilibrist swing-up>", "exec"), ns)
        _NAMESPACES[key] = ns
    return _NAMESPACES[key]


_NAMESPACES: dict[str, dict[str, Any]] = {}


def energy(x: np.ndarray, cp: np.ndarray) -> float:
    """The energy the law pumps (pendulum's from upright; acrobot: total from upright) at state *x*."""
    x = np.asarray(x, dtype=float)
    return float(python_namespace()["su_energy"](x[0], x[1], x[2], x[3], cp))


# --- the controller as a value -----------------------------------------------------


def tracking_gains(noise: float, accel: float, period: float) -> tuple[float, float]:
    """Steady-state alpha-beta gains (Kalata 1984) for sensor noise *noise* and acceleration *accel*."""
    lam = accel * period * period / max(noise, 1e-12)
    r = (4.0 + lam - math.sqrt(8.0 * lam + lam * lam)) / 4.0
    alpha = 1.0 - r * r
    beta = 2.0 * (2.0 - alpha) - 4.0 * math.sqrt(1.0 - alpha)
    return alpha, beta


@dataclass(frozen=True)
class SwingUpTuning:
    """Gains of the pumping law and the supervisor (see the module docstring).

    Attributes
    ----------
    k_energy:
        ``k_E``, per joule (acrobot: the energy's gain on the elbow's acceleration).
    a_max:
        Bound of the pumping term: a cart acceleration [m/s^2] for the
        cart-pole, a torque [N m] for the wheel and the rotary pendulum
        (the acrobot's law does not use it: the motor's limit bounds its torque).
    e0:
        Target energy above upright [J].
    k_x, k_v:
        Centering (cart position) and damping (cart, wheel or arm speed)
        gains; acrobot: ``k_V``, the elbow's damping in ``dV/dt``.
    k_p:
        The acrobot's elbow stiffness ``k_P``.
    catch_fraction, release_factor:
        ``c_in = catch_fraction * c_sat``, ``c_out = release_factor * c_in``.
    accel:
        The acceleration the rate estimator tracks (its process noise) [rad/s^2 or m/s^2].
    k_d:
        The acrobot's ``k_D``, the weight of the elbow's kinetic term in ``V``.
    """

    k_energy: float
    a_max: float
    e0: float = 0.0
    k_x: float = 0.0
    k_v: float = 0.0
    k_p: float = 0.0
    catch_fraction: float = 1.0
    release_factor: float = 4.0
    accel: float = 20.0
    k_d: float = 0.0


#: Default tuning of each law for the catalogue's defaults.
TUNING: Mapping[str, SwingUpTuning] = {
    "cartpole": SwingUpTuning(k_energy=5.0, a_max=6.0, k_x=6.0, k_v=2.0),
    "reaction_wheel_pendulum": SwingUpTuning(k_energy=0.5, a_max=0.2, catch_fraction=10.0, accel=40.0),
    "furuta": SwingUpTuning(k_energy=40.0, a_max=0.05, catch_fraction=20.0, accel=100.0),
    "acrobot": SwingUpTuning(k_energy=1.0, a_max=20.0, k_p=60.0, k_v=30.0, k_d=30.0,
                             release_factor=20.0),
}


class SwingUpRuntime:
    """A swing-up controller run sample by sample from Python, its functions compiled to C.

    The :class:`~equilibrist.control.controller.PythonController` protocol
    (``reset``, ``output``, ``update``, ``rate``, ``outputs``,
    ``estimate``), plus ``mode`` and ``energy`` of the last sample. For
    studies of single runs; simulations compile the same source into the
    core.
    """

    def __init__(self, ctrl: NonlinearController, *, compiled: bool = True) -> None:
        self.ctrl = ctrl
        self.rate: float | None = ctrl.rate
        self.outputs: tuple[str, ...] | None = ctrl.output_names
        self.estimate: np.ndarray | None = None
        self._ns = python_namespace(compiled=compiled)
        self.reset()

    def reset(self) -> None:
        self.z = np.array(self.ctrl.z0)
        self.estimate = None

    @property
    def mode(self) -> str:
        return "balance" if self.z[Z["mode"]] == MODE_BALANCE else "pump"

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        yv = np.ascontiguousarray(y, dtype=float)
        rv = np.ascontiguousarray(r, dtype=float)
        x = np.zeros(N_STATES)
        u = np.zeros(1)
        self._ns["estimate"](float(t), self.z, yv, rv, self.ctrl.params, x)
        self._ns["output"](float(t), self.z, yv, rv, self.ctrl.params, u)
        self.estimate = x
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        zn = np.zeros_like(self.z)
        self._ns["update"](float(t), self.z, np.ascontiguousarray(y, dtype=float),
                           np.ascontiguousarray(r, dtype=float),
                           np.ascontiguousarray(u_applied, dtype=float), self.ctrl.params, zn)
        self.z = zn


# --- building it -------------------------------------------------------------------


def _physics(system: System, law: str) -> list[float]:
    p = system.params
    if law == "cart":
        j = p["I_p"] + p["m_p"] * p["l"] ** 2
        vals = [j, p["m_p"] * p["g"] * p["l"], p["m_c"] + p["m_p"], p["b_c"], p["m_p"] * p["l"],
                p["b_p"]]
    elif law == "wheel":
        j = p["I"] + p["m"] * p["L"] ** 2 + p["m_w"] * p["L_w"] ** 2
        vals = [j, (p["m"] * p["L"] + p["m_w"] * p["L_w"]) * p["g"]]
    elif law == "rotary":
        vals = [p["I_p"] + p["m_p"] * p["l_p"] ** 2, p["m_p"] * p["g"] * p["l_p"]]
    else:
        vals = [p[k] for k in ("m1", "m2", "l1", "lc1", "lc2", "I1", "I2", "g")]
    return vals + [0.0] * (N_PHYS - len(vals))


def catch_level(K: np.ndarray, S: np.ndarray, u_room: np.ndarray) -> float:
    """The largest ``c`` with ``|K dx|_j <= u_room_j`` on the whole ellipse ``dx' S dx <= c``."""
    Sinv = np.linalg.inv(S)
    spread = np.einsum("ij,jk,ik->i", K, Sinv, K)
    return float(np.min(u_room**2 / spread))


def swingup(
    system: System,
    *,
    design: Design | None = None,
    tuning: SwingUpTuning | None = None,
    rate: float | None = None,
    balance: str = "lqr",
) -> NonlinearController:
    """The swing-up controller of *system* (cart-pole, reaction wheel, rotary pendulum, acrobot).

    Parameters
    ----------
    system:
        A bound system with a swing-up law (:data:`LAWS`).
    design:
        The balancing design (a discrete one at the controller's rate);
        default ``design(system, rate=rate)``.
    tuning:
        Gains; default :data:`TUNING` of the system.
    rate:
        Sample rate [Hz]; default the design's, else the rig's ``control_rate``.
    balance:
        What balances after the catch: ``"lqr"`` (the design's discrete LQR on
        the controller's own alpha-beta estimate) or ``"lqg"`` (the design's
        Kalman filter, in its ``current`` or ``predictor`` form, started at
        the hand-over from the alpha-beta estimate, and the LQR on its
        estimate; the tracker keeps running for a hand-back to pumping).

    Returns
    -------
    NonlinearController
        Named ``"swingup"``; its ``settings`` record the law, the tuning and
        the catch levels.

    Raises
    ------
    ControllerError
        A system without a swing-up law, a design at another rate, or an
        unknown *balance*.
    """
    from equilibrist.control.design import design as make_design

    if balance not in BALANCES:
        raise ControllerError(f"balance {balance!r}: expected one of {', '.join(BALANCES)}")
    if system.name not in LAWS:
        raise ControllerError(
            f"{system.name} has no swing-up: it exists for {', '.join(LAWS)}"
        )
    law = LAW_NAMES[LAWS[system.name]]
    if rate is not None:
        hz = float(rate)
    elif design is not None and design.rate is not None:
        hz = float(design.rate)
    else:
        hz = float(system.spec.control_rate)
    if design is None:
        design = make_design(system, rate=hz)
    if design.rate is None or not math.isclose(float(design.rate), hz):
        raise ControllerError(
            f"the swing-up needs a balancing design at {hz:g} Hz: design(system, rate={hz:g})"
        )
    tune = tuning or TUNING[system.name]
    names = system.state_names
    nq = len(system.spec.coordinates)
    n = 2 * nq
    eq = design.plant
    x_op, u_op = np.asarray(eq.x0, dtype=float), np.asarray(eq.u0, dtype=float)
    lo, hi = system.input_limits
    K = np.asarray(design.K, dtype=float).reshape(1, n)
    S = np.asarray(design.S, dtype=float)
    room = np.minimum(hi - u_op, u_op - lo)
    c_in = tune.catch_fraction * catch_level(K, S, room)
    noise = [float(system.spec.sensor_noise.get(c, 1e-3)) for c in system.spec.coordinates]
    alpha, beta = tracking_gains(max(noise), tune.accel, 1.0 / hz)
    cp = np.zeros(CP["end"])
    values = {
        "law": LAWS[system.name], "T": 1.0 / hz, "ke": tune.k_energy, "amax": tune.a_max,
        "e0": tune.e0, "kx": tune.k_x, "kv": tune.k_v, "kp": tune.k_p, "kd": tune.k_d, "c_in": c_in,
        "c_out": tune.release_factor * c_in, "alpha": alpha, "beta": beta,
        "u_min": lo[0], "u_max": hi[0], "u_op": u_op[0],
        "lqg": 1.0 if balance == "lqg" else 0.0,
        "kform": 1.0 if design.kalman_form == "predictor" else 0.0,
    }
    for key, value in values.items():
        cp[CP[key]] = value
    cp[CP["phys"]:CP["phys"] + N_PHYS] = _physics(system, law)
    cp[CP["x_op"]:CP["x_op"] + n] = x_op
    cp[CP["K"]:CP["K"] + n] = K[0]
    cp[CP["S"]:CP["S"] + n * n] = S.reshape(-1)
    for i in range(nq):
        cp[CP["wrap"] + i] = 1.0 if system.state_units[i] == "rad" else 0.0
    if law in ("wheel", "rotary"):
        cp[CP["free"]] = 1.0
    # The design's Kalman filter: Ad, Bd, and its gain with one column per coordinate
    # (zero for a coordinate the design does not measure).
    disc = design.discrete
    if disc is None:
        raise ControllerError(f"the swing-up needs a discrete balancing design: design(system, rate={hz:g})")
    cp[CP["Ad"]:CP["Ad"] + n * n] = np.asarray(disc.A, dtype=float).reshape(-1)
    cp[CP["Bd"]:CP["Bd"] + n] = np.asarray(disc.B, dtype=float).reshape(-1)
    Kf = np.asarray(design.Kf, dtype=float).reshape(n, -1)
    gain = np.zeros((n, 2))
    for col, out in enumerate(eq.output_names):
        gain[:, names.index(out)] = Kf[:, col]
    cp[CP["Kf"]:CP["Kf"] + 2 * n] = gain.reshape(-1)
    settings = {
        "law": law, "balance": balance, "kalman_form": design.kalman_form if balance == "lqg" else "",
        "c_in": c_in, "c_out": tune.release_factor * c_in,
        "alpha": alpha, "beta": beta,
        "tuning": {k: getattr(tune, k) for k in tune.__dataclass_fields__},
    }
    return NonlinearController(
        name="swingup", source=controller_source(), params=cp, z0=np.zeros(Z["end"]),
        rate=hz, x_op=x_op, u_op=u_op, state_names=names, input_names=system.input_names,
        output_names=tuple(names[:nq]), has_estimate=True, settings=settings,
    )


def balance_design(system: System, rate: float | None = None) -> Design:
    """The balancing design the swing-up hands over to (the default discrete LQR)."""
    from equilibrist.control.design import design as make_design

    return make_design(system, rate=float(rate if rate is not None else system.spec.control_rate))
