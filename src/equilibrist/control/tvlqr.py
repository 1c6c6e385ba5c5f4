"""Time-varying LQR: track a planned trajectory, then balance (``--controller tvlqr``).

Along a plan of :mod:`equilibrist.control.trajopt`, sampled at the
controller's rate, the dynamics are linearized at each sample's planned
state and input (the system's exact Jacobians) and sampled with zero-order
hold; the discrete finite-horizon Riccati recursion runs backward from the
balancing LQR's own Riccati solution at the end,

    K_k = (R + B_k' S_k+1 B_k)^-1 B_k' S_k+1 A_k
    S_k = Q + A_k' S_k+1 (A_k - B_k K_k),

with the balancing design's weights (Bryson's rule), so the hand-over to the
balancing LQR at the plan's end is seamless. The command is

    u_k = u_plan(t_k) - K_k (x_k - x_plan(t_k))          while the plan runs,
    u_k = u_op - K (x_k - x_op)                           after it,

on the full measured state (``balance="lqr"``); both stages are one
:class:`~equilibrist.control.controller.NonlinearController` whose tables are
its parameters, so it runs in the compiled core like the swing-up.

*Measured outputs* (``balance="lqg"``). The controller measures the
design's outputs ``y = C x`` (states, so ``C`` selects them) and acts on an
estimate. Its state ``z`` is the predicted estimate ``xhat_{k|k-1}``
(absolute), started at the plan's first state. Along the plan a
time-varying Kalman filter predicts along the plan's own linearizations,

    xhat_k   = z_k + M_k (y_k - C z_k)                       (current form)
    u_k      = u_plan_k - K_k (xhat_k - x_plan_k)
    z_k+1    = x_plan_k+1 + A_k (xhat_k - x_plan_k) + B_k (u_k - u_plan_k),

``u_k`` the command that acted (saturated), or in the predictor form
``xhat_k = z_k`` and ``z_k+1 = x_plan_k+1 + A_k (z_k - x_plan_k) + B_k (u_k -
u_plan_k) + L_k (y_k - C z_k)``, the design's ``kalman_form``. The gains come
from the forward covariance recursion at build time, from ``P_0`` (unless given,
Bryson's scales squared, ``1 / Q_ii``, on the design's stationary a-priori
covariance: the start may be as far from the plan's as the design accepts) with the design's
noise sampled at each linearization (``Qd_k``: Van Loan, or ``G QN G' T``
for an Euler design; ``Rd`` the design's),

    M_k = P_k C' (C P_k C' + Rd)^-1,   L_k = A_k M_k,
    P_k+1 = A_k ((I - M_k C) P_k (I - M_k C)' + M_k Rd M_k') A_k' + Qd_k.

After the plan the same sums run with the design's stationary filter about
the operating point (``Ad``, ``Bd``, its ``Kf``) and the balancing gain:
the contract's LQG, its state the same estimate handed over unchanged.
All of it is built in :mod:`equilibrist.control.fixed`'s order (the same
bits on every CPU).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import compensation, fixed, swingup, torque_lag, tvlqr_rig
from equilibrist.control.discretize import discrete_matrices
from equilibrist.control.kalman import KALMAN, Estimator, estimator, joseph, predict_covariance
from equilibrist.control.nonlinear import BALANCES, CATCH_SOURCE, NonlinearController
from equilibrist.errors import ControllerError
from equilibrist.native.linear_layout import Layout

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.controllers.kinds import ControllerRequest
    from equilibrist.numeric.system import System

#: The most samples a plan may span at the controller's rate (its tables are parameters).
MAX_SAMPLES = 200_000
#: The parameters of ``balance="lqr"``, packed and read through this one layout: the plan's
#: samples (states, inputs) and gains, then the balancing LQR (its operating point, gain and
#: Riccati solution, whose level set is the catch region).
LAYOUT = Layout("TV", ("steps", "knots", "rate", "n", "m", "level"), (
    ("xs", ("knots", "n")), ("us", ("knots", "m")), ("gains", ("steps", "m", "n")),
    ("x_op", ("n",)), ("u_op", ("m",)), ("K_end", ("m", "n")), ("S_end", ("n", "n"))))

#: ``balance="lqg"``: the same, and the filters: the state each output measures, the plan's
#: linearizations and time-varying gains, the design's stationary filter (``current`` is 1
#: for the current form, 0 for the predictor).
LAYOUT_LQG = Layout("TV", ("steps", "knots", "rate", "n", "m", "ny", "current", "level"), (
    ("xs", ("knots", "n")), ("us", ("knots", "m")), ("gains", ("steps", "m", "n")),
    ("x_op", ("n",)), ("u_op", ("m",)), ("K_end", ("m", "n")), ("sel", ("ny",)),
    ("A", ("steps", "n", "n")), ("B", ("steps", "n", "m")), ("F", ("steps", "n", "ny")),
    ("Ad", ("n", "n")), ("Bd", ("n", "m")), ("Kf", ("n", "ny")), ("S_end", ("n", "n"))))

#: ``balance="lqr"`` with its angles wrapped (``wrap=True``): the same, and each state's
#: period (``2 pi`` for an angle, 0 for a state compared as it is).
LAYOUT_WRAP = Layout("TV", LAYOUT.slots, (*LAYOUT.blocks, ("period", ("n",))))

#: The layout of each ``balance``.
LAYOUTS = {"lqr": LAYOUT, "lqg": LAYOUT_LQG}

_LAW = '''
def tv_sample(t, params):
    return int(math.floor(t * params[TV_RATE] + 0.5))


def tv_at(params, slot):
    return int(params[slot])
'''

# The tracker's catch and command, shared by both forms below: only how a state's
# deviation from the plan is taken differs ({deviation}).
_TRACK = '''

def tvlqr_caught(t, z, y, params):
    if tv_sample(t, params) >= tv_at(params, TV_STEPS) or z[0] >= 0.5:
        return 1.0
    n = tv_at(params, TV_N)
    v = catch_level(t, z, y, params, params[tv_at(params, TV_O_S_END):], n)
    return catch_mode(0, v, params[TV_LEVEL], params[TV_LEVEL])


def output(t, z, y, r, params, u_out):
    n = tv_at(params, TV_N)
    m = tv_at(params, TV_M)
    k = tv_sample(t, params)
    ox = tv_at(params, TV_O_X_OP)
    ou = tv_at(params, TV_O_U_OP)
    og = tv_at(params, TV_O_K_END)
    if tvlqr_caught(t, z, y, params) < 0.5:
        ox = tv_at(params, TV_O_XS) + k * n
        ou = tv_at(params, TV_O_US) + k * m
        og = tv_at(params, TV_O_GAINS) + k * m * n
    for i in range(m):
        acc = params[ou + i]
        for j in range(n):
            acc -= params[og + i * n + j] * {deviation}
        u_out[i] = acc


def update(t, z, y, r, u_applied, params, z_out):
    z_out[0] = tvlqr_caught(t, z, y, params)
'''

SOURCE = LAYOUT.source() + CATCH_SOURCE + _LAW + '''

def catch_dev(i, t, z, y, params):
    return y[i] - params[tv_at(params, TV_O_X_OP) + i]
''' + _TRACK.replace("{deviation}", "(y[j] - params[ox + j])")


#: ``balance="lqr"`` with ``wrap=True``: every deviation from the plan or the balance taken
#: modulo its state's period into ``[-period/2, period/2)``, so an angle a turn away is where
#: it is (a rig that swung over, or was pushed over, is caught upright again).
SOURCE_WRAP = LAYOUT_WRAP.source() + CATCH_SOURCE + _LAW + '''

def tv_dev(j, y, params, of):
    d = y[j] - params[of + j]
    period = params[tv_at(params, TV_O_PERIOD) + j]
    if period > 0.0:
        d = d - period * math.floor(d / period + 0.5)
    return d


def catch_dev(i, t, z, y, params):
    return tv_dev(i, y, params, tv_at(params, TV_O_X_OP))
''' + _TRACK.replace("{deviation}", "tv_dev(j, y, params, ox)")


#: ``balance="lqr"`` with rates differenced from the measured angles (``rates="differenced"``):
#: the wrapped layout (every period 0 without ``wrap``) and the number of coordinates.
LAYOUT_DIFF = Layout("TV", (*LAYOUT.slots, "nq"), LAYOUT_WRAP.blocks)

#: ``rates="differenced"``: the rates the law uses are not the measured ones but second-order
#: backward differences of the measured angles, ``(3 q_k - 4 q_k-1 + q_k-2) T^-1 / 2`` (exact
#: for a parabola), as a rig computes them from its encoders: noise on the measured rates never
#: reaches the torque. The state keeps the last two angle readings and how many there are; until
#: there are two, the measured rates are used. Every deviation is taken as ``wrap`` says (a
#: period of 0 compares a state as it is).
SOURCE_DIFF = LAYOUT_DIFF.source() + CATCH_SOURCE + _LAW + '''

def tv_y(j, z, y, params):
    nq = tv_at(params, TV_NQ)
    if j < nq or z[1 + 2 * nq] < 1.5:
        return y[j]
    i = j - nq
    return (3.0 * y[i] - 4.0 * z[1 + i] + z[1 + nq + i]) * (params[TV_RATE] / 2.0)


def tv_dev(j, z, y, params, of):
    d = tv_y(j, z, y, params) - params[of + j]
    period = params[tv_at(params, TV_O_PERIOD) + j]
    if period > 0.0:
        d = d - period * math.floor(d / period + 0.5)
    return d


def catch_dev(i, t, z, y, params):
    return tv_dev(i, z, y, params, tv_at(params, TV_O_X_OP))
''' + _TRACK.replace("{deviation}", "tv_dev(j, z, y, params, ox)").replace(
    "    z_out[0] = tvlqr_caught(t, z, y, params)\n", '''    z_out[0] = tvlqr_caught(t, z, y, params)
    nq = tv_at(params, TV_NQ)
    for i in range(nq):
        z_out[1 + i] = y[i]
        z_out[1 + nq + i] = z[1 + i]
    z_out[1 + 2 * nq] = z[1 + 2 * nq] + 1.0
    if z_out[1 + 2 * nq] > 2.0:
        z_out[1 + 2 * nq] = 2.0
''')

#: What ``rates`` takes: the measured rates as the loop hands them, or differenced.
RATES = ("measured", "differenced")


def periods(system: System) -> np.ndarray:
    """Each state's period for ``wrap=True``: ``2 pi`` for a coordinate in radians (a turn
    of a revolute joint), 0 for the others (lengths, rates)."""
    return np.array([2 * np.pi if name in system.spec.coordinates
                     and system.spec.state_unit(name) == "rad" else 0.0
                     for name in system.state_names])


def lqg_source(est: Estimator | None = None) -> str:
    """The source of ``balance="lqg"``: the same law on the estimate of the estimator *est*
    (default :func:`~equilibrist.control.kalman.estimator`), its functions embedded: the
    plan's time-varying filter, then the design's stationary one; ``z`` is ``xhat_{k|k-1}``."""
    return LAYOUT_LQG.source() + (est or estimator()).source + CATCH_SOURCE + _LAW + '''

def tvkf_stage(t, z, y, params):
    """The tables of this sample: the plan's at its sample k, or the balance's after the catch
    (reference state, input, next reference, gain, A, B, filter gain)."""
    n = tv_at(params, TV_N)
    m = tv_at(params, TV_M)
    ny = tv_at(params, TV_NY)
    k = tv_sample(t, params)
    if tvkf_caught(t, z, y, params) < 0.5:
        return (tv_at(params, TV_O_XS) + k * n, tv_at(params, TV_O_US) + k * m,
                tv_at(params, TV_O_XS) + (k + 1) * n, tv_at(params, TV_O_GAINS) + k * m * n,
                tv_at(params, TV_O_A) + k * n * n, tv_at(params, TV_O_B) + k * n * m,
                tv_at(params, TV_O_F) + k * n * ny)
    return (tv_at(params, TV_O_X_OP), tv_at(params, TV_O_U_OP), tv_at(params, TV_O_X_OP),
            tv_at(params, TV_O_K_END), tv_at(params, TV_O_AD), tv_at(params, TV_O_BD),
            tv_at(params, TV_O_KF))


def tvkf_xhat(j, z, y, params, of):
    """State j of the estimate, the filter's gain at params[of]."""
    return kf_estimate(j, z, y, params[of:], tv_at(params, TV_NY), params[tv_at(params, TV_O_SEL):],
                       params[0:0], params[0:0], params[TV_CURRENT])


def catch_dev(i, t, z, y, params):
    of = tv_at(params, TV_O_F) + tv_sample(t, params) * tv_at(params, TV_N) * tv_at(params, TV_NY)
    return tvkf_xhat(i, z, y, params, of) - params[tv_at(params, TV_O_X_OP) + i]


def tvkf_caught(t, z, y, params):
    n = tv_at(params, TV_N)
    if tv_sample(t, params) >= tv_at(params, TV_STEPS) or z[n] >= 0.5:
        return 1.0
    v = catch_level(t, z, y, params, params[tv_at(params, TV_O_S_END):], n)
    return catch_mode(0, v, params[TV_LEVEL], params[TV_LEVEL])


def output(t, z, y, r, params, u_out):
    n = tv_at(params, TV_N)
    m = tv_at(params, TV_M)
    oxr, our, oxn, ogk, oak, obk, ofk = tvkf_stage(t, z, y, params)
    for i in range(m):
        acc = params[our + i]
        for j in range(n):
            acc -= params[ogk + i * n + j] * (tvkf_xhat(j, z, y, params, ofk) - params[oxr + j])
        u_out[i] = acc


def update(t, z, y, r, u_applied, params, z_out):
    n = tv_at(params, TV_N)
    m = tv_at(params, TV_M)
    ny = tv_at(params, TV_NY)
    oxr, our, oxn, ogk, oak, obk, ofk = tvkf_stage(t, z, y, params)
    for i in range(n):
        z_out[i] = kf_predict(i, params[oxn + i], z, y, params[oak:], params[obk:], params[ofk:],
                              n, m, ny, params[tv_at(params, TV_O_SEL):], params[0:0],
                              params[0:0], params[TV_CURRENT], params[oxr:], u_applied,
                              params[our:])
    z_out[n] = tvkf_caught(t, z, y, params)


def estimate(t, z, y, r, params, x_out):
    n = tv_at(params, TV_N)
    oxr, our, oxn, ogk, oak, obk, ofk = tvkf_stage(t, z, y, params)
    for j in range(n):
        x_out[j] = tvkf_xhat(j, z, y, params, ofk)
'''


#: ``balance="lqg"`` with the Kalman filter (:data:`~equilibrist.control.kalman.KALMAN`).
SOURCE_LQG = lqg_source(KALMAN)


def plan_samples(ctrl: NonlinearController) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, states, inputs)``: the plan as the tracker *ctrl* samples it (at its rate, from
    its tables: the Hermite interpolant of the knots)."""
    layout = (LAYOUT_DIFF if ctrl.settings.get("rates") == "differenced"
              else LAYOUT_WRAP if ctrl.settings.get("wrap")
              else LAYOUTS[str(ctrl.settings["balance"])])
    p = np.asarray(ctrl.params, dtype=float)
    steps, rate = int(p[layout.slots.index("steps")]), float(p[layout.slots.index("rate")])
    return np.arange(steps + 1) / rate, layout.read(p, "xs"), layout.read(p, "us")


def _hermite_states(system: System, traj: Trajectory, t: np.ndarray) -> np.ndarray:
    """The plan's states at times *t*: the cubic Hermite interpolant of the knots and their rates."""
    f = np.array([system.f(x, u) for x, u in zip(traj.states, traj.inputs, strict=True)])
    k = np.clip(np.searchsorted(traj.times, t, side="right") - 1, 0, traj.knots - 1)
    h = (traj.times[k + 1] - traj.times[k])[:, None]
    s = ((t - traj.times[k]) / h[:, 0])[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    states: np.ndarray = (h00 * traj.states[k] + h10 * h * f[k] + h01 * traj.states[k + 1]
                          + h11 * h * f[k + 1])
    return states


def shared_gains(models: Sequence[System], xs: np.ndarray, us: np.ndarray, *, dt: float,
                  Q: np.ndarray, R: np.ndarray, S_end: np.ndarray) -> np.ndarray:
    """The gains shared by several plants along one plan: each sample's gain minimizes the sum
    of the plants' costs-to-go (each plant linearized at the plan's state and input), each
    plant's cost-to-go then propagated under that gain,

        K_k = (sum_i R + B_i' S_i B_i)^-1 sum_i B_i' S_i A_i,
        S_i = Q + K_k' R K_k + (A_i - B_i K_k)' S_i (A_i - B_i K_k),

    from the balancing LQR's ``S_end`` for every plant."""
    n, m = xs.shape[1], us.shape[1]
    steps = xs.shape[0] - 1
    S = [np.array(S_end, dtype=float) for _ in models]
    gains = np.zeros((steps, m, n))
    for k in range(steps - 1, -1, -1):
        sampled = [discrete_matrices(*p.jacobians(xs[k], us[k]), dt) for p in models]
        G = np.zeros((m, m))
        H = np.zeros((m, n))
        for (Ad, Bd), Si in zip(sampled, S, strict=True):
            G = G + (R + fixed.mm(Bd.T, Si, Bd))
            H = H + fixed.mm(Bd.T, Si, Ad)
        Kk = fixed.solve(G, H)
        for i, (Ad, Bd) in enumerate(sampled):
            closed = Ad - fixed.matmul(Bd, Kk)
            S[i] = fixed.symmetric(Q + fixed.mm(Kk.T, R, Kk) + fixed.mm(closed.T, S[i], closed))
        gains[k] = Kk
    return gains


def tvlqr(system: System, traj: Trajectory, *, rate: float, Q: np.ndarray, R: np.ndarray,
          S_end: np.ndarray, K_end: np.ndarray, x_op: np.ndarray, u_op: np.ndarray,
          balance: str = "lqr", design: Design | None = None, P0: np.ndarray | None = None,
          catch: bool = True, wrap: bool = False,
          rates: str = "measured", plants: Sequence[System] = (),
          friction_compensation: bool = False,
          torque_response: float | None = None) -> NonlinearController:
    """The time-varying LQR along *traj* at *rate*, handing over to ``K_end`` at the end.

    ``balance="lqr"`` acts on the full measured state; ``"lqg"`` on the estimate of
    *design*'s Kalman filter from its outputs, time-varying along the plan from the
    a-priori covariance *P0* (default :func:`start_covariance`), then the design's
    (see the module docstring). With *catch* the balancing stage takes over as soon as
    the state (its estimate) enters :func:`catch_region` before the plan ends. With *wrap*
    (``balance="lqr"`` only) the angles' deviations are taken modulo a turn
    (:data:`SOURCE_WRAP`). With ``rates="differenced"`` (``balance="lqr"`` only) the law's
    rates are differenced from the measured angles (:data:`SOURCE_DIFF`). With *plants*
    (the same system with other parameters: a spread the rig may be anywhere in), the gains
    are shared by *system* and them (:func:`shared_gains`). With *friction_compensation*
    (``balance="lqr"`` only) the command adds the model's friction torque on the actuated
    joints at the state the law uses (:mod:`equilibrist.control.compensation`), and the gains
    and the plan's feedforward are those of the plant with that friction cancelled
    (:func:`equilibrist.control.tvlqr_rig.compensated_plan`); *S_end*, *K_end* should then be the balancing design of
    :func:`~equilibrist.control.compensation.design_system` (a passive joint's Coulomb
    friction as its secant), as :func:`build_request` makes it. With *torque_response*
    (``k`` per period, ``balance="lqr"`` only) the motor's lag is in the design: the plan's
    torque led by its inverse, the gains of the model augmented with the torque state, which
    the controller runs from its own commands (:mod:`equilibrist.control.torque_lag`; the
    balance's gains and the catch region are the augmented model's, not *K_end*, *S_end*).
    """
    if friction_compensation and balance != "lqr":
        raise ControllerError("--friction-compensation on adds the friction at the full "
                              "state's rates: it takes --balance lqr")
    if torque_response is not None and (balance != "lqr" or plants):
        raise ControllerError("--design-torque-response designs the full state's gains with the "
                              "torque state: it takes --balance lqr and one plant")
    if rates not in RATES:
        raise ControllerError(f"--rates {rates!r}: expected one of {', '.join(RATES)}")
    if rates == "differenced" and balance != "lqr":
        raise ControllerError("--rates differenced differences the full state's angles: it "
                              "takes --balance lqr")
    if wrap and balance != "lqr":
        raise ControllerError("--wrap on wraps the full state's angles: it takes --balance lqr")
    if balance not in BALANCES:
        raise ControllerError(f"--balance {balance!r}: expected one of {', '.join(BALANCES)}")
    if balance == "lqg" and design is None:
        raise ControllerError("the time-varying LQR with --balance lqg needs the balancing "
                              "design (its outputs and Kalman filter)")
    if traj.state_names != system.state_names or traj.input_names != system.input_names:
        raise ControllerError(f"the trajectory is of states {', '.join(traj.state_names)} and inputs "
                              f"{', '.join(traj.input_names)}: not {system.key}'s")
    steps = int(np.floor(traj.duration * rate + 1e-9))
    if not 1 <= steps <= MAX_SAMPLES:
        raise ControllerError(f"the trajectory spans {steps} samples at {rate:g} Hz: expected 1 to "
                              f"{MAX_SAMPLES}")
    n, m = system.n_states, system.n_inputs
    dt = 1.0 / rate
    t = traj.times[0] + np.arange(steps + 1) * dt
    xs = _hermite_states(system, traj, t)
    us = traj.input_at(t).reshape(steps + 1, m)
    # Without friction the controller is the one without compensation, to the bit.
    comp = compensation.compensation(system) if friction_compensation else None
    plant_system = system
    if comp is not None:
        plant_system, us = tvlqr_rig.compensated_plan(system, comp, traj, xs, us)
    S = np.array(S_end, dtype=float)
    gains = np.zeros((steps, m, n))
    plant: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    if plants:
        gains = shared_gains([plant_system, *plants], xs, us, dt=dt, Q=Q, R=R, S_end=S)
    lag = None
    if torque_response is not None:
        # The balance of the plant the compensation leaves is designed as build_request's
        # (a passive joint's Coulomb friction as its secant).
        at_rest = plant_system if comp is None else compensation.design_system(system, comp)
        lag = tvlqr_rig.lag_gains(plant_system, at_rest, xs, us, rate=rate, Q=Q, R=R,
                      kappa=torque_response, x_op=x_op, u_op=u_op)
        gains, K_end, S_end = lag[0][:, :, :n], lag[1][:, :n], lag[2][:n, :n]
    for k in range(steps - 1, -1, -1) if lag is None else ():
        A, B = plant_system.jacobians(xs[k], us[k])
        Ad, Bd = discrete_matrices(A, B, dt)
        if balance == "lqg":
            plant.append((A, Ad, Bd))
        if plants:
            continue
        # In the fixed order of control.fixed, as every sampled design: the same bits on
        # every CPU (numpy's @ and LAPACK follow the BLAS kernel the CPU selects).
        G = R + fixed.mm(Bd.T, S, Bd)
        Kk = fixed.solve(G, fixed.mm(Bd.T, S, Ad))
        S = fixed.symmetric(Q + fixed.mm(Ad.T, S, Ad - fixed.matmul(Bd, Kk)))
        gains[k] = Kk
    if not np.all(np.isfinite(gains)):
        raise ControllerError("the time-varying LQR's Riccati recursion did not stay finite along "
                              "the trajectory")
    S_end = np.asarray(S_end, dtype=float)
    level = swingup.catch_region(system, np.asarray(K_end, dtype=float), S_end, u_op) if catch else -1.0
    if balance == "lqg":
        assert design is not None
        return _with_filter(system, traj, design, plant[::-1], xs, us, gains, rate=rate,
                            x_op=x_op, u_op=u_op, K_end=K_end, S_end=S_end, level=level, P0=P0)
    blocks = {"xs": xs, "us": us, "gains": gains, "x_op": x_op, "u_op": u_op, "K_end": K_end,
              "S_end": S_end}
    sizes = {"steps": steps, "knots": steps + 1, "rate": rate, "n": n, "m": m, "level": level}
    differenced = rates == "differenced"
    params, source, z0 = _packed(system, sizes, blocks, wrap=wrap, differenced=differenced)
    params, source, z0, settings = tvlqr_rig.with_rig(system, params, source, z0, comp=comp, lag=lag,
                                             kappa=torque_response, u_op=u_op,
                                             differenced=differenced)
    return NonlinearController(
        name="tvlqr", source=source, params=params, z0=z0,
        rate=float(rate),
        x_op=x_op, u_op=u_op, state_names=system.state_names, input_names=system.input_names,
        output_names=system.state_names,
        settings={"kind": "tvlqr", "trajectory_duration": traj.duration, "samples": steps,
                  "start": dict(zip(system.state_names, traj.states[0].tolist(), strict=True)),
                  "balance": "lqr", "catch_level": level, **({"wrap": True} if wrap else {}),
                  **({"rates": "differenced"} if differenced else {}), **settings},
    )


def _packed(system: System, sizes: Mapping[str, float], blocks: Mapping[str, object], *,
            wrap: bool, differenced: bool) -> tuple[np.ndarray, str, np.ndarray]:
    """The ``balance="lqr"`` tracker's parameters, source and start state in the layout of
    its form (measured, wrapped, or with its rates differenced)."""
    n = system.n_states
    nq = int(system.functions.N_Q)
    if differenced and (nq == 0 or n != 2 * nq):
        raise ControllerError(f"--rates differenced needs a state [q, q_dot]: {system.key}'s is "
                              f"{', '.join(system.state_names)}")
    if differenced:
        period = periods(system) if wrap else np.zeros(n)
        params = LAYOUT_DIFF.pack({**sizes, "nq": nq}, {**blocks, "period": period})
        return params, SOURCE_DIFF, np.zeros(2 + 2 * nq)
    if wrap:
        return LAYOUT_WRAP.pack(sizes, {**blocks, "period": periods(system)}), SOURCE_WRAP, \
            np.zeros(1)
    return LAYOUT.pack(sizes, blocks), SOURCE, np.zeros(1)


def output_selection(design: Design, state_names: tuple[str, ...]) -> tuple[int, ...]:
    """The state measured by each of *design*'s outputs: its ``C`` must select states."""
    plant = design.plant
    C = np.asarray(plant.C, dtype=float)
    index = []
    for row, name in enumerate(plant.output_names):
        if name not in state_names:
            raise ControllerError(f"the design's output {name!r} is not a state: the time-varying "
                                  "filter measures states")
        want = np.zeros(len(state_names))
        want[state_names.index(name)] = 1.0
        if not np.array_equal(C[row], want):
            raise ControllerError(f"the design's output {name!r} is not the state itself (its row "
                                  "of C selects no single state)")
        index.append(state_names.index(name))
    return tuple(index)


def start_covariance(design: Design) -> np.ndarray:
    """The filter's a-priori covariance where the plan starts: Bryson's scales squared
    (``1 / Q_ii``, the largest deviation the design accepts: how far the start may be from
    the plan's) on the design's stationary ``P`` (which keeps it definite where ``Q_ii = 0``).

    The stationary ``P`` alone trusts the plan's start as a converged filter would: a start
    0.05 rad off is then forgotten over some 0.5 s instead of a few samples."""
    q = np.diag(np.asarray(design.Q, dtype=float))
    scales = np.where(q > 0, 1.0 / np.where(q > 0, q, 1.0), 0.0)
    return fixed.symmetric(np.asarray(design.P, dtype=float) + np.diag(scales))


def kalman_along(plant: list[tuple[np.ndarray, np.ndarray, np.ndarray]], C: np.ndarray,
                 design: Design, dt: float, P0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The time-varying Kalman filter along the plan's linearizations ``(A, Ad, Bd)``.

    Returns the gains ``(steps, n, ny)`` in the design's form (``M_k`` current, ``L_k =
    Ad_k M_k`` predictor) and the a-priori covariances ``(steps + 1, n, n)``, ``P_0`` first.
    """
    from equilibrist.control.discretize import discrete_noise

    rule = estimator().gain
    n, ny = C.shape[1], C.shape[0]
    if design.Rd is None:
        raise ControllerError("the time-varying filter needs a discrete design (its Rd)")
    Rd = np.asarray(design.Rd, dtype=float)
    G, QN, RN = (np.asarray(v, dtype=float) for v in (design.G, design.QN, design.RN))
    P = fixed.symmetric(np.asarray(P0, dtype=float))
    gains = np.zeros((len(plant), n, ny))
    covariances = np.zeros((len(plant) + 1, n, n))
    covariances[0] = P
    held: np.ndarray | None = None
    Qd = np.zeros((n, n))
    for k, (A, Ad, _Bd) in enumerate(plant):
        M = rule(P, C, Rd)
        posterior = joseph(P, M, C, Rd)
        if A is not held:  # the same linearization again (a plan held still): the same Qd
            Qd, _ = discrete_noise(A, G, QN, RN, dt, method=design.discretization)
            held = A
        P = predict_covariance(posterior, Ad, Qd)
        gains[k] = M if design.kalman_form == "current" else fixed.matmul(Ad, M)
        covariances[k + 1] = P
    if not (np.all(np.isfinite(gains)) and np.all(np.isfinite(covariances))):
        raise ControllerError("the time-varying Kalman filter did not stay finite along the "
                              "trajectory")
    return gains, covariances


def _with_filter(system: System, traj: Trajectory, design: Design,
                 plant: list[tuple[np.ndarray, np.ndarray, np.ndarray]], xs: np.ndarray,
                 us: np.ndarray, gains: np.ndarray, *, rate: float, x_op: np.ndarray,
                 u_op: np.ndarray, K_end: np.ndarray, S_end: np.ndarray, level: float,
                 P0: np.ndarray | None) -> NonlinearController:
    """The ``balance="lqg"`` controller: the gains on the estimate of the filters."""
    names = system.state_names
    n, m, steps = system.n_states, system.n_inputs, gains.shape[0]
    index = output_selection(design, names)
    disc = design.discrete
    if disc is None or design.rate is None or not np.isclose(float(design.rate), rate):
        raise ControllerError(f"the time-varying filter needs the balancing design at {rate:g} Hz")
    C = np.zeros((len(index), n))
    for row, j in enumerate(index):
        C[row, j] = 1.0
    start = np.asarray(start_covariance(design) if P0 is None else P0, dtype=float)
    if start.shape != (n, n):
        raise ControllerError(f"P0 has shape {start.shape}: expected ({n}, {n})")
    filters, _ = kalman_along(plant, C, design, 1.0 / rate, start)
    params = LAYOUT_LQG.pack(
        {"steps": steps, "knots": steps + 1, "rate": rate, "n": n, "m": m, "ny": len(index),
         "current": 1.0 if design.kalman_form == "current" else 0.0, "level": level},
        {"xs": xs, "us": us, "gains": gains, "x_op": x_op, "u_op": u_op, "K_end": K_end,
         "sel": np.asarray(index, dtype=float), "A": np.array([a for _, a, _ in plant]),
         "B": np.array([b for _, _, b in plant]), "F": filters, "Ad": disc.A, "Bd": disc.B,
         "Kf": design.Kf, "S_end": S_end})
    return NonlinearController(
        name="tvlqr", source=lqg_source(), params=params, z0=np.concatenate([xs[0], [0.0]]),
        rate=float(rate),
        x_op=x_op, u_op=u_op, state_names=names, input_names=system.input_names,
        output_names=design.plant.output_names, has_estimate=True,
        settings={"kind": "tvlqr", "trajectory_duration": traj.duration, "samples": steps,
                  "start": dict(zip(names, traj.states[0].tolist(), strict=True)),
                  "balance": "lqg", "kalman_form": design.kalman_form, "catch_level": level,
                  "outputs": list(design.plant.output_names)},
    )


def build_request(request: ControllerRequest) -> NonlinearController:
    from equilibrist.control.trajectory_file import load_trajectory
    from equilibrist.control.trajopt import Trajectory

    path = request.options.get("trajectory")
    if path is None:
        raise ControllerError("--controller tvlqr tracks a planned trajectory: give --trajectory "
                              "FILE.npz (equilibrist trajopt SYSTEM --out FILE.npz)")
    # From Python, the plan itself (equilibrist.policy(..., trajectory=plan(...))).
    traj = path if isinstance(path, Trajectory) else load_trajectory(path)
    system = request.system
    if traj.state_names != system.state_names or traj.input_names != system.input_names:
        raise ControllerError(f"{path} is a trajectory of {traj.system}, not of {system.key} "
                              "(its states or inputs differ)")
    compensate = str(request.options.get("friction_compensation", "off"))
    if compensate not in ("on", "off"):
        raise ControllerError(f"--friction-compensation {compensate!r}: expected on or off")
    bare = None
    if compensate == "on":
        bare = compensation.design_system(system, compensation.compensation(system))
    if bare is not None and dict(bare.params) != dict(system.params):
        # The balance is designed for the plant the compensation leaves: the actuated
        # joints' friction cancelled, a passive joint's Coulomb friction as its secant.
        from equilibrist.control.design import design as make_design

        design = make_design(bare, rate=request.sample_rate, **dict(request.design_options))
    else:
        design = request.design()
    if design.discrete is None:
        raise ControllerError("the time-varying LQR needs a discrete design (a rate)")
    rate = float(design.rate or system.spec.control_rate)
    balance = str(request.options.get("balance", "lqr"))
    catch = str(request.options.get("catch", "on"))
    if catch not in ("on", "off"):
        raise ControllerError(f"--catch {catch!r}: expected on or off")
    wrap = str(request.options.get("wrap", "off"))
    if wrap not in ("on", "off"):
        raise ControllerError(f"--wrap {wrap!r}: expected on or off")
    rates = str(request.options.get("rates", "measured"))
    response = request.options.get("design_torque_response")
    kappa = None if response is None else torque_lag.response_k(response, rate)
    return tvlqr(system, traj, rate=rate, Q=design.Q, R=design.R, S_end=design.S, K_end=design.K,
                 x_op=design.plant.x0, u_op=design.plant.u0, balance=balance, design=design,
                 catch=catch == "on", wrap=wrap == "on", rates=rates,
                 friction_compensation=compensate == "on", torque_response=kappa)
