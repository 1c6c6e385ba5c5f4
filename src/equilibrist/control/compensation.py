"""Friction compensation: the model's own friction torque on the actuated joints, added to a
controller's command (``--friction-compensation on``).

A motor can cancel the friction of the joint it drives, not a passive joint's. The friction
is the system's own, read from its derived model, never written here: a friction is a
parameter the definition marks ``dissipative`` (:class:`~equilibrist.mechanics.spec.Parameter`:
viscous damping, or a Coulomb friction in the smooth law the model names,
:mod:`equilibrist.mechanics.friction`). The model's generalized friction force is what the
dissipative parameters add to the generalized forces,

    Delta F(x) = M(q) (q_ddot(x, u; p) - q_ddot(x, u; p with the frictions at zero)),

evaluated by the system's generated functions (``scalar_qdd``, ``scalar_mass``, copied into
the controller's source as the swing-up copies them), so any law the model uses (``b v``,
``cf atan(100 v)``, ``cf tanh(100 v)``, a friction that depends on the position) is
cancelled as the model has it. The frictions compensated are the dissipative parameters
whose force acts on the actuated coordinates alone (the actuated joints' damping and
Coulomb friction; a passive joint's is left to the loop), each input driving one coordinate
``a`` with a constant generalized force per unit ``c`` (``dF_a/du = c``); the command of
input ``i`` gains

    u_i += -Delta F_a(x) / c

at the state the controller has (measured, differenced or estimated: the hosting source's
``fc_x(j, t, z, y, params)``). The plant the rest of the controller is designed for is then
the system with those frictions at zero (:func:`compensated_system`).

The compensation's parameters are a block at the end of the controller's own
(:data:`LAYOUT`, read from ``params.shape[0] - FC_END``), so the hosting controller's layout
and its source stay as they were.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import ControllerError
from equilibrist.native.linear_layout import Layout

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

#: The compensation's block: the system's parameters as they are (``phys``) and with the
#: compensated frictions at zero (``bare``), each input's coordinate (``joint``) and its
#: generalized force per unit input (``gain``).
LAYOUT = Layout("FC", ("np", "m"), (("phys", ("np",)), ("bare", ("np",)), ("joint", ("m",)),
                                    ("gain", ("m",))))

#: Where a passive joint's Coulomb friction is linearized for the balance, as a share of the
#: design's scale of its rate: the mean speed of rates spread evenly over the scale. (At the
#: whole scale, 1 rad/s, the pendubot's balance held four of the seven RealAIGym rigs with
#: their identified friction; at a half, or a quarter, all seven: bench/README.md.)
SPEED = 0.5

#: The states at which an input's direction and a friction's reach are checked: positions
#: over a turn, rates from the smooth Coulomb law's knee (0.01) to a swing's (10).
_PROBES = 12


@dataclass(frozen=True)
class Compensation:
    """What a controller of *system* compensates: the frictions (parameter names) whose force
    acts on the actuated coordinates alone, each input's coordinate and its generalized force
    per unit input."""

    parameters: tuple[str, ...]
    joints: tuple[int, ...]
    gains: tuple[float, ...]


def _probes(system: System) -> np.ndarray:
    nq = int(system.functions.N_Q)
    rng = np.random.default_rng(0)
    q = rng.uniform(-np.pi, np.pi, (_PROBES, nq))
    v = rng.uniform(-1.0, 1.0, (_PROBES, nq)) * 10.0 ** rng.uniform(-2.0, 1.0, (_PROBES, nq))
    return np.hstack([q, v])


def _mass(system: System, x: np.ndarray) -> np.ndarray:
    nq = int(system.functions.N_Q)
    out = np.zeros((nq, nq))
    system.functions.mass_matrix(np.asarray(x, dtype=float), system.p, out)
    return out


def _forces(system: System, p: np.ndarray, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``M(q) q_ddot(x, u; p)``: the generalized forces of parameters *p* at *x*, *u*."""
    nq = int(system.functions.N_Q)
    out = np.zeros(system.n_states)
    system.functions.f(np.asarray(x, dtype=float), np.asarray(u, dtype=float), p, out)
    return _mass(system, x) @ out[nq:]


def _zeroed(system: System, names: tuple[str, ...]) -> np.ndarray:
    p = np.array(system.p, dtype=float)
    for name in names:
        p[system.spec.parameter_names.index(name)] = 0.0
    return p


def compensation(system: System) -> Compensation:
    """The frictions a controller of *system* can compensate, and how each input acts.

    Raises :class:`~equilibrist.errors.ControllerError` when the system has no mass matrix
    (not a mechanical model ``[q, q_dot]``) or an input does not drive one coordinate with a
    constant generalized force."""
    module = system.functions
    nq = int(getattr(module, "N_Q", 0))
    if nq == 0 or system.n_states != 2 * nq or not hasattr(module, "mass_matrix"):
        raise ControllerError(f"--friction-compensation needs a mechanical model [q, q_dot]: "
                              f"{system.key}'s state is {', '.join(system.state_names)}")
    probes = _probes(system)
    m = system.n_inputs
    p = np.array(system.p, dtype=float)
    joints: list[int] = []
    gains: list[float] = []
    for i, name in enumerate(system.input_names):
        unit = np.zeros(m)
        unit[i] = 1.0
        directions = np.array([_forces(system, p, x, unit) - _forces(system, p, x, np.zeros(m))
                               for x in probes])
        scale = float(np.max(np.abs(directions)))
        driven = np.flatnonzero(np.max(np.abs(directions), axis=0) > 1e-9 * scale)
        if scale == 0.0 or driven.size != 1 or np.ptp(directions[:, driven[0]]) > 1e-9 * scale:
            raise ControllerError(f"--friction-compensation: {system.key}'s input {name} does "
                                  "not drive one coordinate with a constant force")
        joints.append(int(driven[0]))
        gains.append(float(np.median(directions[:, driven[0]])))
    passive = [j for j in range(nq) if j not in joints]
    compensated = []
    for parameter in system.spec.parameters:
        if not parameter.dissipative or system.params[parameter.name] == 0.0:
            continue
        bare = _zeroed(system, (parameter.name,))
        force = np.array([_forces(system, p, x, np.zeros(m)) - _forces(system, bare, x, np.zeros(m))
                          for x in probes])
        scale = float(np.max(np.abs(force)))
        if scale > 0.0 and float(np.max(np.abs(force[:, passive]), initial=0.0)) <= 1e-9 * scale:
            compensated.append(parameter.name)
    return Compensation(tuple(compensated), tuple(joints), tuple(gains))


def compensated_system(system: System, comp: Compensation) -> System:
    """*system* with the compensated frictions at zero: the plant the motor leaves (what a
    plan through it is made on)."""
    return system.with_params(**{name: 0.0 for name in comp.parameters})


def _single_coordinate(force: np.ndarray) -> int | None:
    """The one coordinate a force (probes x coordinates) acts on, or None."""
    reach = np.max(np.abs(force), axis=0)
    scale = float(np.max(reach))
    acting = np.flatnonzero(reach > 1e-9 * scale) if scale > 0.0 else np.zeros(0, dtype=int)
    return int(acting[0]) if acting.size == 1 else None


def design_system(system: System, comp: Compensation) -> System:
    """The plant a compensated controller's balance is designed for (at rest, the operating
    point): the compensated frictions at zero, and each Coulomb friction left (a passive
    joint's) as the viscous damping it acts as over the rates the design expects.

    A smooth Coulomb law's slope at rest (``100 cf`` for ``cf atan(100 v)``) holds only below
    some 0.01 rad/s; linearized there, a passive joint looks locked to the design, and a
    balance designed so loses the rig. The friction enters instead as its secant ``F(V) / V``
    at the mean speed of rates spread evenly over the design's scale of that rate,
    ``V = SPEED * scale`` (:data:`SPEED`; the scale is the system's Bryson scale of the
    rate, 1 where it has none), added to the joint's viscous damping parameter (a
    dissipative parameter whose force is linear in that joint's rate alone); a Coulomb
    friction without one is left as it is."""
    bare = compensated_system(system, comp)
    nq = int(system.functions.N_Q)
    m = system.n_inputs
    probes = _probes(system)
    coulomb = [p for p in system.spec.parameters
               if p.coulomb and p.name not in comp.parameters and system.params[p.name] != 0.0]
    viscous = [p for p in system.spec.parameters if p.dissipative and not p.coulomb]
    changes: dict[str, float] = {}
    for parameter in coulomb:
        p = np.array(bare.p, dtype=float)
        without = _zeroed(bare, (parameter.name,))
        force = np.array([_forces(bare, p, x, np.zeros(m)) - _forces(bare, without, x, np.zeros(m))
                          for x in probes])
        joint = _single_coordinate(force)
        if joint is None:
            continue
        for damping in viscous:
            unit = np.array(without, dtype=float)
            index = system.spec.parameter_names.index(damping.name)
            unit[index] += 1.0
            per = np.array([_forces(bare, unit, x, np.zeros(m)) - _forces(bare, without, x, np.zeros(m))
                            for x in probes])
            if _single_coordinate(per) != joint:
                continue
            ratio = per[:, joint] / probes[:, nq + joint]
            if np.ptp(ratio) > 1e-9 * np.max(np.abs(ratio)) or ratio[0] >= 0.0:
                continue  # not a damping linear in the joint's rate
            rate_name = system.state_names[nq + joint]
            scale = SPEED * float(system.spec.design_scales.get(rate_name, 1.0))
            at = np.array(system.operating_point().x, dtype=float)
            at[nq + joint] = scale
            secant = abs(float((_forces(bare, p, at, np.zeros(m))
                                - _forces(bare, without, at, np.zeros(m)))[joint])) / scale
            changes[parameter.name] = 0.0
            changes[damping.name] = changes.get(damping.name, float(system.params[damping.name])) \
                + secant / float(-ratio[0])
            break
    return bare.with_params(**changes)


def torque(system: System, comp: Compensation, x: np.ndarray) -> np.ndarray:
    """The compensation's command at state *x* (one per input): ``-Delta F_a / c`` of the
    compensated frictions, *system*'s parameters (its Python form, for tables and checks)."""
    m = system.n_inputs
    delta = (_forces(system, np.array(system.p, dtype=float), x, np.zeros(m))
             - _forces(system, _zeroed(system, comp.parameters), x, np.zeros(m)))
    return np.array([-delta[j] / c for j, c in zip(comp.joints, comp.gains, strict=True)])


def block(system: System, comp: Compensation) -> np.ndarray:
    """The compensation's parameters (:data:`LAYOUT`), to append to the controller's."""
    return LAYOUT.pack({"np": system.p.size, "m": system.n_inputs},
                       {"phys": system.p, "bare": _zeroed(system, comp.parameters),
                        "joint": np.asarray(comp.joints, dtype=float),
                        "gain": np.asarray(comp.gains, dtype=float)})


def source(system: System) -> str:
    """The source of ``fc_torque(i, t, z, y, params)`` (the compensation of input ``i`` at the
    state ``fc_x(j, t, z, y, params)`` the hosting source defines) and of the system's
    generated physics it calls."""
    from equilibrist.control.swingup_law import physics_source

    n, m = system.n_states, system.n_inputs
    nq = int(system.functions.N_Q)
    sizes = {"np": system.p.size, "m": m}
    head = LAYOUT.source(sizes) + f"FC_NQ = {nq}\n"
    states = ", ".join(f"x{j}" for j in range(n))
    unpack = "".join(f"    x{j} = fc_x({j}, t, z, y, params)\n" for j in range(n))
    rest = ", ".join(["0.0"] * m)
    return head + f'''

def fc_torque(i, t, z, y, params):
    """Input i's share of the compensation: minus the compensated frictions' generalized
    force on its coordinate, M(q) times the accelerations they cause, over its gain."""
    o = int(params.shape[0]) - FC_END
{unpack}    a = int(params[o + FC_JOINT + i])
    force = 0.0
    for j in range(FC_NQ):
        d = (scalar_qdd(j, {states}, {rest}, params, o + FC_PHYS)
             - scalar_qdd(j, {states}, {rest}, params, o + FC_BARE))
        force += scalar_mass(a, j, {states}, params, o + FC_PHYS) * d
    return -force / params[o + FC_GAIN + i]
''' + "\n\n" + physics_source(system)
