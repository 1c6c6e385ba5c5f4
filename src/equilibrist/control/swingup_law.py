"""The swing-up's law as source: the layout of its parameters ``cp`` and state ``z`` (one
place for the source, the Python and the C export), the energy-shaping law itself
(:data:`LAW_SOURCE`), the controller's source and its namespace as Python; split from
:mod:`equilibrist.control.swingup`, which re-exports them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.numeric.system import System

# --- layout of the parameters ``cp`` and of the state ``z`` (one place: the source,
# the Python runtime and the C export read these) -----------------------------------
CP_SLOTS = ("T", "ke", "amax", "e0", "kx", "kv", "kp", "c_in", "c_out", "alpha",
            "beta", "u_min", "u_max", "u_op", "kd", "lqg", "kform", "e_up")
N_STATES = 4  # every rig with a swing-up has two coordinates
#: The blocks after the slots; the last, ``phys``, is the system's own parameter vector (as
#: long as the system has parameters), which the system's generated functions read.
CP_BLOCKS = (("x_op", N_STATES), ("K", N_STATES), ("S", N_STATES * N_STATES),
             ("wrap", N_STATES), ("free", N_STATES), ("Ad", N_STATES * N_STATES),
             ("Bd", N_STATES), ("Kf", N_STATES * 2), ("phys", 0))
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


# The pieces the laws' sources share: the energies and the start of every pumping term (the
# energy's error and the gains). The physics is the system's own: its generated functions
# (``scalar_energy``, ``scalar_mass``, ``scalar_qdd`` of :mod:`equilibrist.numeric.codegen`),
# copied into the controller's source, on its parameters (the ``phys`` block).
_PENDULUM_ENERGY = """
def su_energy(x0, x1, x2, x3, p):
    # The pendulum's energy from upright: its inertia (the mass matrix's entry of the
    # pendulum's coordinate) times its rate squared over two, and the rig's energy at rest.
    o = SU_PHYS
    kin = 0.5 * scalar_mass(1, 1, x0, x1, x2, x3, p, o) * x3 * x3
    return kin + scalar_energy(x0, x1, 0.0, 0.0, p, o) - p[SU_E_UP]
"""
_TOTAL_ENERGY = """
def su_energy(x0, x1, x2, x3, p):
    # The rig's total energy, from upright.
    return scalar_energy(x0, x1, x2, x3, p, SU_PHYS) - p[SU_E_UP]
"""


def _pump(body: str) -> str:
    """``su_pump`` with *body* after the shared start (``ph``, ``e``, ``ke``, ``amax``)."""
    return """

def su_pump(x0, x1, x2, x3, p):
    ph = SU_PHYS
    e = su_energy(x0, x1, x2, x3, p) - p[SU_E0]
    ke = p[SU_KE]
    amax = p[SU_AMAX]
""" + body


#: Each law's energy and pumping term, as source (``su_energy``, ``su_pump``): the controller's
#: source is the common part (:data:`LAW_SOURCE`), the law its system's definition names
#: (``spec.swingup.law``), with no branch on a law number, and the system's generated functions
#: the law calls (:func:`physics_source`).
LAW_SOURCES = {
    "cart": _PENDULUM_ENERGY + _pump("""    a = su_clip(ke * e * su_sign(x3 * eq_cos(x1)), -amax, amax)
    a = a - p[SU_KX] * x0 - p[SU_KV] * x2
    # The force that gives the cart the acceleration a exactly: the cart's acceleration is
    # affine in the force.
    free = scalar_qdd(0, x0, x1, x2, x3, 0.0, p, ph)
    per_newton = scalar_qdd(0, x0, x1, x2, x3, 1.0, p, ph) - free
    return (a - free) / per_newton
"""),
    "wheel": _PENDULUM_ENERGY + _pump("""    return su_clip(ke * e * su_sign(x3), -amax, amax) - p[SU_KV] * (x2 - x3)
"""),
    "rotary": _PENDULUM_ENERGY + _pump("""    return su_clip(ke * e * su_sign(x3 * eq_cos(x1)), -amax, amax) - p[SU_KV] * x2
"""),
    "acrobot": _TOTAL_ENERGY + _pump("""    t2 = su_wrap(x1)
    m11 = scalar_mass(0, 0, x0, t2, x2, x3, p, ph)
    m12 = scalar_mass(0, 1, x0, t2, x2, x3, p, ph)
    m22 = scalar_mass(1, 1, x0, t2, x2, x3, p, ph)
    det = m11 * m22 - m12 * m12
    # The bias and gravity terms hg of M q_ddot + hg = B tau: minus M times the accelerations
    # without torque.
    a1 = scalar_qdd(0, x0, t2, x2, x3, 0.0, p, ph)
    a2 = scalar_qdd(1, x0, t2, x2, x3, 0.0, p, ph)
    hg1 = -(m11 * a1 + m12 * a2)
    hg2 = -(m12 * a1 + m22 * a2)
    # Xin and Kaneda's energy law: V = ke (E - E0)^2 / 2 + kd x3^2 / 2 + kp t2^2 / 2
    # falls as dV/dt = -kv x3^2 (while the motor is not saturated).
    kd = p[SU_KD]
    num = -(p[SU_KV] * x3 + p[SU_KP] * t2) * det + kd * (m11 * hg2 - m12 * hg1)
    den = ke * e * det + kd * m11
    if den == 0.0:
        return 0.0
    return num / den
"""),
}
LAW_NAMES = tuple(LAW_SOURCES)


#: The system's generated functions a law calls (:mod:`equilibrist.numeric.codegen`).
PHYSICS_FUNCTIONS = ("scalar_qdd", "scalar_mass", "scalar_energy")


def physics_source(system: System) -> str:
    """The source of *system*'s generated functions the laws call (:data:`PHYSICS_FUNCTIONS`),
    as its derived module holds them: the system's own physics, no sympy at run time."""
    import inspect

    module = system.functions
    missing = [name for name in PHYSICS_FUNCTIONS if not hasattr(module, name)]
    if missing:
        from equilibrist.errors import ControllerError

        raise ControllerError(f"{system.name}'s model has no {', '.join(missing)}: the swing-up "
                              "needs a mechanical model (a mass matrix)")
    return "\n\n".join(inspect.getsource(getattr(module, name)) for name in PHYSICS_FUNCTIONS)


def controller_source(law: str, physics: str) -> str:
    """The swing-up's source for the law *law* (:data:`LAW_NAMES`) on a system's *physics*
    (:func:`physics_source`): the layout's constants, :data:`LAW_SOURCE`, the law's
    :data:`LAW_SOURCES` and the physics."""
    head = "\n".join(f"{k} = {v}" for k, v in layout_constants().items())
    return head + "\n" + LAW_SOURCE + LAW_SOURCES[law] + "\n\n" + physics


class ControllerNamespace(Protocol):
    """A controller's functions by name (:func:`python_namespace`): the namespace its source
    ran in as Python, or its functions compiled to C
    (:class:`~equilibrist.control.compiled.ControllerFunctions`)."""

    def __getitem__(self, name: str, /) -> Callable[..., Any]: ...


def python_namespace(source: str, *, compiled: bool = False) -> ControllerNamespace:
    """A swing-up's controller functions from its *source*, as plain Python (or compiled to C,
    as the simulation core runs them, when *compiled*: then only ``output``, ``update`` and
    ``estimate``)."""
    if compiled:
        from equilibrist.control.compiled import controller_functions

        return controller_functions(source, ("output", "update", "estimate"))
    if source not in _NAMESPACES:
        from equilibrist.control.nonlinear import contract_namespace

        ns = contract_namespace()
        exec(compile(source, "<equilibrist swing-up>", "exec"), ns)
        if len(_NAMESPACES) > 32:
            _NAMESPACES.clear()
        _NAMESPACES[source] = ns
    return _NAMESPACES[source]


_NAMESPACES: dict[str, ControllerNamespace] = {}


def energy(x: np.ndarray, ctrl: NonlinearController) -> float:
    """The energy the swing-up *ctrl* pumps (the pendulum's, or the acrobot's total), from
    upright, at state *x*."""
    x = np.asarray(x, dtype=float)
    return float(python_namespace(ctrl.source)["su_energy"](x[0], x[1], x[2], x[3], ctrl.params))
