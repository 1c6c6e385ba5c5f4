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

*Energy shaping on the collocated joint* for the acrobot and the pendubot
(Xin and Kaneda, "Analysis of the energy-based swing-up control of the
Acrobot", Int. J. Robust Nonlinear Control 17 (2007); Fantoni, Lozano and
Spong, "Energy based control of the Pendubot", IEEE Trans. Automatic Control
45 (2000); both on the partial feedback linearization of Spong 1995, "The
swing up control problem for the acrobot", IEEE Control Systems 15). ``E``
is the total energy from upright; with the motor at joint ``a`` (the
acrobot's elbow, the pendubot's shoulder) it changes at the rate ``dE/dt =
tau qa_dot``. The motor's torque is the one that makes
``V = k_E (E - E0)^2 / 2 + k_D qa_dot^2 / 2 + k_P qa~^2 / 2`` (``qa~`` the
actuated joint's distance from upright) fall as ``dV/dt = -k_V qa_dot^2``:
``tau = (-(k_V qa_dot + k_P qa~) det M + k_D (M_bb hg_a - M_ab hg_b)) /
(k_E (E - E0) det M + k_D M_bb)`` (``M`` the inertia matrix, ``hg`` the
velocity and gravity terms, ``b`` the passive joint). The rig tends to the
upright's energy with the actuated joint upright and still: the acrobot's
link 1 swinging as one rigid pendulum on its homoclinic orbit, the
pendubot's link 2 on its own above a still link 1.

*Gains in the rig's own scales.* Only the ratios ``k_D / k_E``, ``k_P / k_E``
and ``k_V / k_E`` shape the law, and each has a scale of the rig
(:func:`plant_scales`, from its generated energy and mass matrix):

* ``k_D``: the denominator keeps its sign on every state the energy may
  reach (``E >= E_min(q2)``, the lowest the rig hangs with that bend) when
  ``k_D / k_E > max over q2 of (E_up - E_min(q2)) det M / M_bb`` (Xin and
  Kaneda's condition); ``k_d_bound`` is ``k_D`` over that bound.
* ``k_P``: at rest ``tau`` is gravity's torque ``G_a`` on the actuated joint
  where gravity leaves the passive joint still, and the law rests there when
  ``k_P qa~ = -k_E (E - E0) G_a``: ``k_P`` above ``k_E max(-(E - E0) G_a /
  qa~)`` over those points leaves the closed loop no resting point but
  hanging and upright (``2 b1 b2`` for the acrobot, ``b1``, ``b2`` the links'
  gravity torques, met bending a little off hanging); ``k_p_bound`` is ``k_P``
  over it. The pendubot has no such point to push away; its ``k_P`` is stated
  by the torque it asks hanging at rest half a turn from upright:
  ``k_P pi = k_p_torque k_E lift torque_room`` (``k_p_torque`` of the motor's
  room, ``lift = E_up - E_hanging``).
* ``k_V = 2 zeta sqrt(k_P k_D)``: near the end, where ``E - E0`` is small,
  the actuated joint obeys ``k_D qa_ddot + k_V qa_dot + k_P qa~ = 0``, of
  damping ratio ``zeta``.

The default tunings (the rigs' definitions) state ``k_d_bound``,
``k_p_bound`` (or ``k_p_torque``) and ``zeta``: one tuning swings up the
catalogue's acrobot (1 kg m^2 links, 20 N m) and DFKI's (0.05 kg m^2, 6 N m).

*Pump from rest.* Hanging at rest every term of the acrobot's law is zero
(a rate, a bend or a force of a rig at rest), so it would never move; a weak
shoulder motor cannot lift the pendubot's links by pushing. Below the energy
``E_hanging + kick_energy lift`` the motor pushes with ``kick`` of its room
along the actuated joint's rate (along its angle when the rate is zero, up
when both are): ``dE/dt = kick |qa_dot| >= 0``, so the energy rises
monotonically out of that pit and the law takes over.

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
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import fixed
from equilibrist.control.nonlinear import BALANCES, NonlinearController
from equilibrist.control.swingup_law import (
    CP_SLOTS,
    LAW_NAMES,
    LAYOUT,
    MODE_BALANCE,
    Z,
    controller_source,
    physics_source,
    python_namespace,
    z_layout,
)
from equilibrist.control.swingup_scales import ACTUATED, plant_scales
from equilibrist.errors import ControllerError

if TYPE_CHECKING:

    from equilibrist.control.design_record import Design
    from equilibrist.mechanics.spec import SwingUp
    from equilibrist.numeric.system import System


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
        The two-link laws' ``k_D``, the weight of the actuated joint's kinetic term in ``V``.
    kick, kick_energy:
        The two-link laws' pump from rest: below ``kick_energy`` of the lift above hanging,
        the torque ``kick`` (a share of the motor's room to its limit) along the actuated
        joint's rate. 0: no pump.
    k_d_bound, k_p_bound, k_p_torque, zeta:
        The two-link laws' gains in the rig's own scales (:class:`PlantScales`), in place of
        ``k_d``, ``k_p``, ``k_v`` (``k_d_bound > 0`` selects them): ``k_E = k_energy / lift``,
        ``k_D = k_d_bound k_E damping_bound``, ``k_P = k_E (k_p_bound stiffness_bound +
        k_p_torque lift torque / pi)``, ``k_V = 2 zeta sqrt(k_P k_D)``.
    """

    k_energy: float
    a_max: float = 0.0
    e0: float = 0.0
    k_x: float = 0.0
    k_v: float = 0.0
    k_p: float = 0.0
    catch_fraction: float = 1.0
    release_factor: float = 4.0
    accel: float = 20.0
    k_d: float = 0.0
    kick: float = 0.0
    kick_energy: float = 0.0
    k_d_bound: float = 0.0
    k_p_bound: float = 0.0
    k_p_torque: float = 0.0
    zeta: float = 0.0


def swingup_laws() -> dict[str, str]:
    """The catalogue's systems (their keys, a variant's with its option) with a swing-up
    (``spec.swingup``), and the law of each."""
    from equilibrist.systems.registry import all_entries

    return {e.spec.key: e.spec.swingup.law for e in all_entries() if e.spec.swingup is not None}


def _stated(system: System) -> SwingUp:
    """*system*'s swing-up as its definition states it; refused if it states none."""
    stated = system.spec.swingup
    if stated is None:
        raise ControllerError(f"{system.name} has no swing-up: it exists for "
                              f"{', '.join(swingup_laws())}")
    unknown = [c for c in stated.free if c not in system.spec.coordinates]
    if unknown:
        raise ControllerError(f"{system.name}'s swing-up frees {', '.join(unknown)}: expected "
                              f"coordinates ({', '.join(system.spec.coordinates)})")
    return stated


def default_tuning(system: System) -> SwingUpTuning:
    """The gains *system*'s definition states (``spec.swingup.gains``)."""
    return SwingUpTuning(**_stated(system).gains)


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
        self._ns = python_namespace(ctrl.source, compiled=compiled)
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
        x = np.zeros(len(self.ctrl.state_names))
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


def catch_level(K: np.ndarray, S: np.ndarray, u_room: np.ndarray) -> float:
    """The largest ``c`` with ``|K dx|_j <= u_room_j`` on the whole ellipse ``dx' S dx <= c``."""
    # In control.fixed's order (the level is a parameter of the controller: the same bits on
    # every CPU, as the design it comes from).
    Kt = np.asarray(K, dtype=float)
    X = fixed.solve(np.asarray(S, dtype=float), Kt.T)  # S^-1 K'
    spread = np.array([float(fixed.matmul(Kt[j:j + 1], X[:, j:j + 1])[0, 0])
                       for j in range(Kt.shape[0])])
    return float(np.min(np.asarray(u_room, dtype=float) ** 2 / spread))


def catch_region(system: System, K: np.ndarray, S: np.ndarray, u_op: np.ndarray) -> float:
    """The level ``c`` of the balancing LQR's catch region ``dx' S dx <= c`` (``dx = x -
    x_op``): the largest on which its command ``u_op - K dx`` stays within the input limits
    (:func:`catch_level`), or ``-1`` (never caught before the
    plan ends) where an input has no limit on one side."""
    lo, hi = (np.asarray(v, dtype=float) for v in system.input_limits)
    room = np.minimum(hi - u_op, u_op - lo)
    if not np.all(np.isfinite(room)) or np.any(room <= 0):
        return -1.0
    return catch_level(K, S, room)

def swingup(
    system: System,
    *,
    design: Design | None = None,
    tuning: SwingUpTuning | None = None,
    rate: float | None = None,
    balance: str = "lqr",
) -> SwingUpController:
    """The swing-up controller of *system* (cart-pole, reaction wheel, rotary pendulum, acrobot,
    pendubot).

    Parameters
    ----------
    system:
        A bound system whose definition states a swing-up (``spec.swingup``).
    design:
        The balancing design (a discrete one at the controller's rate);
        default ``design(system, rate=rate)``.
    tuning:
        Gains; default those of the system's definition (:func:`default_tuning`).
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
    stated = _stated(system)
    law = stated.law
    tune = tuning or default_tuning(system)
    if law not in LAW_NAMES:
        raise ControllerError(f"{system.name}'s swing-up law {law!r}: expected one of "
                              f"{', '.join(LAW_NAMES)}")
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
    names = system.state_names
    nq = len(system.spec.coordinates)
    n = 2 * nq
    eq = design.plant
    x_op, u_op = np.asarray(eq.x0, dtype=float), np.asarray(eq.u0, dtype=float)
    lo, hi = system.input_limits
    K = np.asarray(design.K, dtype=float).reshape(1, n)
    S = np.asarray(design.S, dtype=float)
    c_in = tune.catch_fraction * catch_region(system, K, S, u_op)
    noise = [float(system.spec.sensor_noise.get(c, 1e-3)) for c in system.spec.coordinates]
    alpha, beta = tracking_gains(max(noise), tune.accel, 1.0 / hz)
    phys = np.asarray(system.p, dtype=float)
    # The design's Kalman filter: Ad, Bd, and its gain with one column per coordinate
    # (zero for a coordinate the design does not measure).
    disc = design.discrete
    if disc is None:
        raise ControllerError(f"the swing-up needs a discrete balancing design: design(system, rate={hz:g})")
    Kf = np.asarray(design.Kf, dtype=float).reshape(n, -1)
    gain = np.zeros((n, nq))
    for col, out in enumerate(eq.output_names):
        gain[:, names.index(out)] = Kf[:, col]
    slots = {
        "T": 1.0 / hz, "ke": tune.k_energy, "amax": tune.a_max,
        "e0": tune.e0, "kx": tune.k_x, "kv": tune.k_v, "kp": tune.k_p, "kd": tune.k_d, "c_in": c_in,
        "c_out": tune.release_factor * c_in, "alpha": alpha, "beta": beta,
        "u_min": lo[0], "u_max": hi[0], "u_op": u_op[0],
        "lqg": 1.0 if balance == "lqg" else 0.0,
        "current": 1.0 if design.kalman_form == "current" else 0.0,
        "e_up": 0.0, "kick": 0.0, "e_kick": 0.0, "n": n, "nq": nq, "np": phys.size,
    }
    blocks = {
        "x_op": x_op, "K": K[0], "S": S,
        "wrap": [1.0 if i < nq and system.state_units[i] == "rad" else 0.0 for i in range(n)],
        "free": [1.0 if i < nq and system.spec.coordinates[i] in stated.free else 0.0
                 for i in range(n)],
        "Ad": disc.A, "Bd": np.asarray(disc.B, dtype=float).reshape(n), "Kf": gain,
        "sel": np.arange(nq, dtype=float),
        "phys": phys,  # the system's own parameters, which its generated functions read
    }
    cp = LAYOUT.pack(slots, blocks)
    settings = {
        "law": law, "balance": balance, "kalman_form": design.kalman_form if balance == "lqg" else "",
        "c_in": c_in, "c_out": tune.release_factor * c_in,
        "alpha": alpha, "beta": beta,
        "tuning": {k: getattr(tune, k) for k in tune.__dataclass_fields__},
    }
    source = controller_source(law, physics_source(system), n, nq)
    gains = _energy_slots(system, source, cp, law, tune, x_op)
    if gains:
        settings["gains"] = gains
    return SwingUpController(
        name="swingup", source=source, params=cp, z0=np.zeros(z_layout(n)["end"]),
        rate=hz, x_op=x_op, u_op=u_op, state_names=names, input_names=system.input_names,
        output_names=tuple(names[:nq]), has_estimate=True, settings=settings,
    )


def _energy_slots(system: System, source: str, cp: np.ndarray, law: str, tune: SwingUpTuning,
                  x_op: np.ndarray) -> dict[str, float]:
    """Write the slots that need the law's own energy into *cp*: the energy at upright (the
    law's at the operating point, at rest: energies are measured from it), and the two-link
    laws' gains and pump (:func:`_collocated_gains`, returned; empty for the others)."""
    cp[CP_SLOTS.index("e_up")] = python_namespace(source)["su_energy"](*x_op, cp)
    if law not in ACTUATED:
        return {}
    gains = _collocated_gains(system, source, cp, law, tune)
    for slot, value in gains.items():
        cp[CP_SLOTS.index(slot)] = value
    return gains


def _collocated_gains(system: System, source: str, cp: np.ndarray, law: str,
                      tune: SwingUpTuning) -> dict[str, float]:
    """The two-link law's gains in the plant's units: as *tune* states them, or (with
    ``k_d_bound``) from the plant's own scales (:func:`plant_scales`; docs/swingup.md)."""
    sc = plant_scales(system, source, cp, law)
    out = {"ke": tune.k_energy, "kd": tune.k_d, "kp": tune.k_p, "kv": tune.k_v}
    if tune.k_d_bound > 0.0:
        if tune.k_d or tune.k_p or tune.k_v:
            raise ControllerError("the swing-up's tuning states k_d_bound and k_d, k_p or k_v: "
                                  "expected the gains in the plant's scales or in its units, "
                                  "not both")
        ke = tune.k_energy / sc.lift
        kd = tune.k_d_bound * ke * sc.damping_bound
        kp = ke * (tune.k_p_bound * sc.stiffness_bound
                   + tune.k_p_torque * sc.lift * sc.torque / math.pi)
        out = {"ke": ke, "kd": kd, "kp": kp, "kv": 2.0 * tune.zeta * math.sqrt(kp * kd)}
    out["kick"] = tune.kick * sc.torque
    # The kick acts while the energy is within kick_energy of the lift above hanging.
    out["e_kick"] = -sc.lift * (1.0 - tune.kick_energy) - tune.e0
    return out


class SwingUpController(NonlinearController):
    """The swing-up with its supervisor: a :class:`NonlinearController` whose law never reads
    the time (so its C export's functions take none), and whose export records a swing-up
    from hanging, as its task starts one."""

    reads_time = False

    def title(self) -> str:
        law = self.settings.get("law", "")
        balance = str(self.settings.get("balance", "lqr")).upper()
        return f"swing-up with supervisor ({law} law, balanced by the {balance})"

    def record_start(self, system: System, seed: int) -> np.ndarray:
        from equilibrist.tasks import get_task

        return np.asarray(get_task(system, "swingup").draw_initial(np.random.default_rng(seed)),
                          dtype=float)


def balance_design(system: System, rate: float | None = None) -> Design:
    """The balancing design the swing-up hands over to (the default discrete LQR)."""
    from equilibrist.control.design import design as make_design

    return make_design(system, rate=float(rate if rate is not None else system.spec.control_rate))



__all__ = [
    "SwingUpController",
    "SwingUpRuntime",
    "SwingUpTuning",
    "balance_design",
    "catch_level",
    "catch_region",
    "default_tuning",
    "swingup",
    "swingup_laws",
    "tracking_gains",
]
