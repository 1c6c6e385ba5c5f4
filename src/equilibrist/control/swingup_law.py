"""The swing-up's law as source: the layout of its parameters ``cp`` and state ``z`` (one
place for the source, the Python and the C export), the energy-shaping law itself
(:data:`LAW_SOURCE`), the controller's source and its namespace as Python; used by :mod:`equilibrist.control.swingup`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from equilibrist.native.linear_layout import Layout

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.numeric.system import System

# --- layout of the parameters ``cp`` and of the state ``z`` (one place: the source,
# the Python runtime and the C export read these) -----------------------------------
CP_SLOTS = ("T", "ke", "amax", "e0", "kx", "kv", "kp", "c_in", "c_out", "alpha",
            "beta", "u_min", "u_max", "u_op", "kd", "lqg", "current", "e_up", "kick", "e_kick",
            "n", "nq", "np")
#: The parameters: the slots, then the blocks, their sizes in the system's states ``n``, its
#: coordinates ``nq`` (what the rig measures: the filter's outputs, one per coordinate, zero
#: gains for a coordinate the design does not measure) and its parameters ``np``. The last
#: block, ``phys``, is the system's own parameter vector, which its generated functions read.
LAYOUT = Layout("SU", CP_SLOTS, (
    ("x_op", ("n",)), ("K", ("n",)), ("S", ("n", "n")), ("wrap", ("n",)), ("free", ("n",)),
    ("Ad", ("n", "n")), ("Bd", ("n",)), ("Kf", ("n", "nq")), ("sel", ("nq",)), ("phys", ("np",))))

MODE_PUMP, MODE_BALANCE = 0.0, 1.0


def _offsets(slots: tuple[tuple[str, int], ...], start: int = 0) -> dict[str, int]:
    out, at = {}, start
    for name, size in slots:
        out[name] = at
        at += size
    out["end"] = at
    return out


def cp_layout(n: int, nq: int, n_phys: int = 0) -> dict[str, int]:
    """Where each slot and block of the parameters is, for a system of *n* states, *nq*
    coordinates and *n_phys* parameters (``"end"``: the vector's length)."""
    sizes = {"n": n, "nq": nq, "np": n_phys}
    return {**{name: i for i, name in enumerate(CP_SLOTS)}, **LAYOUT.offsets(sizes)}


def z_layout(n: int) -> dict[str, int]:
    """Where each slot of the state ``z`` is, for a system of *n* states: the tracker's start
    flag and the mode (the same for every system), the tracker's estimate, the balance's held
    reference and the filter's prediction (``kz``, a deviation from that reference)."""
    return _offsets((("init", 1), ("mode", 1), ("xhat", n), ("ref", n), ("kz", n)))


#: The layouts of the catalogue's swing-up rigs (two coordinates, four states); a controller's
#: own are :func:`cp_layout` and :func:`z_layout` of its system (the mode's slot is always
#: ``Z["mode"]``).
CP = cp_layout(4, 2)
Z = z_layout(4)


def layout_constants(n: int, nq: int) -> dict[str, int]:
    """The layout as the source's constants (``SU_KE = 1``, ``SU_Z_MODE = 1`` ...) for a
    system of *n* states and *nq* coordinates: the slots' and blocks' places (from
    :data:`LAYOUT`, the object that packs the parameters) and the sizes ``SU_N``, ``SU_NQ``."""
    out = {k: v for k, v in LAYOUT.fixed_constants({"n": n, "nq": nq, "np": 0}).items()
           if not k.startswith("SU_O_") and k != "SU_END"}
    out.update({f"SU_Z_{k.upper()}": v for k, v in z_layout(n).items() if k != "end"})
    out.update({"SU_DIM_N": n, "SU_DIM_NQ": nq})
    return out


#: The law, in the Python the C translation knows: compiled into the simulation core as a
#: :class:`~equilibrist.control.controller.NonlinearController` and run as is in Python,
#: for any number of states (``SU_DIM_N``) and coordinates (``SU_DIM_NQ``). The catch is
#: :data:`~equilibrist.control.nonlinear.CATCH_SOURCE`'s, the Kalman filter of the LQG
#: hand-over the estimator's (:data:`~equilibrist.control.kalman.ESTIMATOR_SOURCE`); the
#: pumping term ``su_pump`` is the law's (:data:`LAW_SOURCES`), called by ``su_law`` with the
#: tracker's estimate (written for the system's states by :func:`controller_source`).
LAW_SOURCE = """
def su_wrap(a):
    return kf_wrap(a)


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
    # The alpha-beta tracker's current estimate of state i (positions first, then rates).
    nq = SU_DIM_NQ
    if z[SU_Z_INIT] == 0.0:
        if i < nq:
            return y[i]
        return 0.0
    if i < nq:
        return z[SU_Z_XHAT + i] + p[SU_ALPHA] * (y[i] - z[SU_Z_XHAT + i])
    return z[SU_Z_XHAT + i] + p[SU_BETA] / p[SU_T] * (y[i - nq] - z[SU_Z_XHAT + i - nq])


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


def catch_dev(i, t, z, y, p):
    # The tracker's deviation of state i from the balance's reference: the catch's.
    x = su_xhat(z, y, p, i)
    return su_dev(x, su_ref(z, x, p, i, z[SU_Z_MODE] == 1.0), p, i)


def su_kest(z, y, p, i):
    # The Kalman filter's estimate (deviation from the held reference) of state i while the
    # LQG balances.
    return kf_estimate(i, z[SU_Z_KZ:], y, p[SU_KF:], SU_DIM_NQ, p[SU_SEL:], z[SU_Z_REF:],
                       p[SU_WRAP:], p[SU_CURRENT])


def su_mode(z, y, p):
    # The catch, with its hysteresis, on the tracker's estimate (the law reads no time).
    v = catch_level(0.0, z, y, p, p[SU_S:], SU_DIM_N)
    return catch_mode(z[SU_Z_MODE] == 1.0, v, p[SU_C_IN], p[SU_C_OUT])


def su_balance(z, y, p, kalman):
    # The balancing LQR's command on the deviation (the filter's, with kalman).
    s = -0.0
    for j in range(SU_DIM_N):
        if kalman:
            s += p[SU_K + j] * su_kest(z, y, p, j)
        else:
            s += p[SU_K + j] * catch_dev(j, 0.0, z, y, p)
    return p[SU_U_OP] - s


def output(t, z, y, r, p, u_out):
    bal = z[SU_Z_MODE] == 1.0
    mode = su_mode(z, y, p)
    if mode == 1.0:
        raw = su_balance(z, y, p, bal and p[SU_LQG] != 0.0)
    else:
        raw = su_law(z, y, p)
    u_out[0] = su_clip(raw, p[SU_U_MIN], p[SU_U_MAX])


def update(t, z, y, r, u_applied, p, z_out):
    n = SU_DIM_N
    nq = SU_DIM_NQ
    bal = z[SU_Z_MODE] == 1.0
    mode = su_mode(z, y, p)
    if p[SU_LQG] != 0.0 and mode == 1.0:
        if bal:
            # The filter runs: its next prediction from its own estimate.
            for i in range(n):
                z_out[SU_Z_KZ + i] = kf_predict(
                    i, -0.0, z[SU_Z_KZ:], y, p[SU_AD:], p[SU_BD:], p[SU_KF:], n, 1, nq,
                    p[SU_SEL:], z[SU_Z_REF:], p[SU_WRAP:], p[SU_CURRENT], p[0:0], u_applied,
                    p[SU_U_OP:])
        else:
            # The hand-over: the filter starts from the tracker's estimate (held in the
            # tracker's slots until they are written below).
            for j in range(n):
                z_out[SU_Z_XHAT + j] = catch_dev(j, 0.0, z, y, p)
            for i in range(n):
                z_out[SU_Z_KZ + i] = kf_predict(
                    i, -0.0, z_out[SU_Z_XHAT:], y, p[SU_AD:], p[SU_BD:], p[SU_KF:], n, 1, 0,
                    p[SU_SEL:], p[0:0], p[SU_WRAP:], 0, p[0:0], u_applied, p[SU_U_OP:])
    else:
        for i in range(n):
            z_out[SU_Z_KZ + i] = 0.0
    z_out[SU_Z_INIT] = 1.0
    z_out[SU_Z_MODE] = mode
    for i in range(n):
        x = su_xhat(z, y, p, i)
        z_out[SU_Z_REF + i] = su_ref(z, x, p, i, bal)
    for i in range(n):
        if i < nq:
            z_out[SU_Z_XHAT + i] = su_xhat(z, y, p, i) + p[SU_T] * su_xhat(z, y, p, i + nq)
        else:
            z_out[SU_Z_XHAT + i] = su_xhat(z, y, p, i)


def estimate(t, z, y, r, p, x_out):
    if z[SU_Z_MODE] == 1.0 and p[SU_LQG] != 0.0:
        for i in range(SU_DIM_N):
            x_out[i] = z[SU_Z_REF + i] + su_kest(z, y, p, i)
        return
    for i in range(SU_DIM_N):
        x_out[i] = su_xhat(z, y, p, i)
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


def _collocated(a: int) -> str:
    """The body of the two-link rigs' law with the motor at joint *a* (0: the shoulder, the
    pendubot's; 1: the elbow, the acrobot's) and joint ``b`` passive: Spong's collocated
    partial feedback linearization under Xin and Kaneda's (acrobot) and Fantoni, Lozano and
    Spong's (pendubot) energy function, and the kick from rest."""
    b = 1 - a
    return f"""    # The pump from rest: near the bottom at rest the law's torque vanishes (its every
    # term is a rate, a bend or a force of a rig at rest), and a weak motor cannot lift a
    # link by pushing: below the energy e_kick the motor pushes with the torque kick along
    # the actuated joint's rate (along its angle when it is still, up when both are zero),
    # so dE/dt = kick |rate| >= 0 until the energy has risen out of that pit.
    if p[SU_KICK] != 0.0 and e < p[SU_E_KICK]:
        s = su_sign(x{a + 2})
        if s == 0.0:
            s = su_sign(x{a})
        if s == 0.0:
            s = 1.0
        return p[SU_KICK] * s
    # The actuated joint's distance from upright, and its rate.
    qa = su_wrap(x{a} - p[SU_X_OP + {a}])
    va = x{a + 2}
    t2 = su_wrap(x1)
    maa = scalar_mass({a}, {a}, x0, t2, x2, x3, p, ph)
    mab = scalar_mass(0, 1, x0, t2, x2, x3, p, ph)
    mbb = scalar_mass({b}, {b}, x0, t2, x2, x3, p, ph)
    det = maa * mbb - mab * mab
    # The bias and gravity terms hg of M q_ddot + hg = B tau: minus M times the accelerations
    # without torque.
    aa = scalar_qdd({a}, x0, t2, x2, x3, 0.0, p, ph)
    ab = scalar_qdd({b}, x0, t2, x2, x3, 0.0, p, ph)
    hga = -(maa * aa + mab * ab)
    hgb = -(mab * aa + mbb * ab)
    # V = ke (E - E0)^2 / 2 + kd va^2 / 2 + kp qa^2 / 2 falls as dV/dt = -kv va^2 (while the
    # motor is not saturated): dE/dt = tau va, and the actuated joint's acceleration is
    # (mbb (tau - hga) + mab hgb) / det.
    kd = p[SU_KD]
    num = -(p[SU_KV] * va + p[SU_KP] * qa) * det + kd * (mbb * hga - mab * hgb)
    den = ke * e * det + kd * mbb
    if den == 0.0:
        return 0.0
    return num / den
"""


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
    "acrobot": _TOTAL_ENERGY + _pump(_collocated(1)),
    "pendubot": _TOTAL_ENERGY + _pump(_collocated(0)),
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


def controller_source(law: str, physics: str, n: int, nq: int) -> str:
    """The swing-up's source for the law *law* (:data:`LAW_NAMES`) on a system's *physics*
    (:func:`physics_source`) of *n* states and *nq* coordinates: the layout's constants,
    the estimator's source (:func:`~equilibrist.control.kalman.estimator`), the catch's,
    :data:`LAW_SOURCE`, the law's :data:`LAW_SOURCES` (``su_law`` hands it the tracker's
    estimate, state by state) and the physics."""
    from equilibrist.control.kalman import estimator
    from equilibrist.control.nonlinear import CATCH_SOURCE

    head = "\n".join(f"{k} = {v}" for k, v in layout_constants(n, nq).items())
    states = ", ".join(f"su_xhat(z, y, p, {i})" for i in range(n))
    call = f"\n\ndef su_law(z, y, p):\n    return su_pump({states}, p)\n"
    return (head + "\n" + estimator().source + CATCH_SOURCE + LAW_SOURCE + LAW_SOURCES[law]
            + call + "\n\n" + physics)


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
    return float(python_namespace(ctrl.source)["su_energy"](*x, ctrl.params))
