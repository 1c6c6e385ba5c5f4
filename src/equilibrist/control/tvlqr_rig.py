"""The time-varying LQR with what it knows of the rig: the friction of the motor's joint
cancelled (:mod:`equilibrist.control.compensation`, ``--friction-compensation on``) and the
motor's first-order lag designed for (:mod:`equilibrist.control.torque_lag`,
``--design-torque-response``): the plant and feedforward the gains are designed on, the
gains of the model with the torque state, and the tracker's source and parameters extended
by each (:func:`equilibrist.control.tvlqr.tvlqr` builds the tracker; docs/trajopt.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import compensation, torque_lag

if TYPE_CHECKING:
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.system import System


def with_rig(system: System, params: np.ndarray, source: str, z0: np.ndarray, *,
              comp: compensation.Compensation | None,
              lag: tuple[np.ndarray, np.ndarray, np.ndarray] | None, kappa: float | None,
              u_op: np.ndarray, differenced: bool
              ) -> tuple[np.ndarray, str, np.ndarray, dict[str, object]]:
    """The tracker with what it knows of the rig: the motor's lag (its block after the
    tracker's parameters, the torque state after its state) and the friction compensation
    (its block last), and the settings that say so."""
    n, m = system.n_states, system.n_inputs
    settings: dict[str, object] = {}
    fc_block = np.zeros(0)
    if comp is not None:
        settings["friction_compensation"] = list(comp.parameters)
        designed = compensation.design_system(system, comp)
        settings["friction_design"] = {k: v for k, v in designed.params.items()
                                       if v != system.params[k]}
    if comp is not None and comp.parameters:
        fc_block = compensation.block(system, comp)
        source = compensated_source(source, system, differenced=differenced)
    if lag is not None and kappa is not None:
        params = np.concatenate([params, torque_lag.block(
            system, kappa=kappa, end=lag[1][:, n:], tau_gains=lag[0][:, :, n:])])
        source = lagged_source(source, n=n, m=m, tail=fc_block.size)
        z0 = np.concatenate([z0, torque_lag.start(system, u_op)])
        settings["torque_response"] = kappa
    return np.concatenate([params, fc_block]), source, z0, settings


def lag_gains(system: System, at_rest: System, xs: np.ndarray, us: np.ndarray, *, rate: float,
            Q: np.ndarray, R: np.ndarray, kappa: float, x_op: np.ndarray,
            u_op: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The augmented model's gains along the plan ``(steps, m, n + m)`` (*system*'s), its
    balancing gain ``(m, n + m)`` and Riccati solution (*at_rest*'s, at the operating point)
    (:mod:`equilibrist.control.torque_lag`)."""
    K_aug, S_aug = torque_lag.balance(at_rest, x_op, u_op, rate=rate, Q=Q, R=R, kappa=kappa)
    along = torque_lag.gains(system, xs, us, rate=rate, Q=Q, R=R, kappa=kappa, S_end=S_aug)
    return along, K_aug, S_aug


def lagged_source(source: str, *, n: int, m: int, tail: int) -> str:
    """A ``balance="lqr"`` tracker's *source* that knows the motor's lag: its command adds
    the lag's lead and the torque state's feedback, its update steps the torque state (the
    last *m* entries of its state) (:func:`equilibrist.control.torque_lag.source`; *tail*:
    the values after the lag's block in the parameters)."""
    head = "    z_out[0] = tvlqr_caught(t, z, y, params)\n"
    lagged = source.replace("        u_out[i] = acc",
                            "        u_out[i] = acc + lg_torque(i, t, z, y, params)")
    lagged = lagged.replace(head, head + "    lg_update(t, z, u_applied, params, z_out)\n")
    if lagged.count("lg_torque") != 1 or lagged.count("lg_update") != 1:
        raise AssertionError("the tracker's source has no command or update to extend")
    return lagged + "\n\n" + torque_lag.source(n=n, m=m, tail=tail)


def compensated_source(source: str, system: System, *, differenced: bool) -> str:
    """A ``balance="lqr"`` tracker's *source* whose command adds the friction compensation
    (:func:`equilibrist.control.compensation.source`) at the state its law uses: the
    measured one, or with its rates differenced (*differenced*)."""
    state = "tv_y(j, z, y, params)" if differenced else "y[j]"
    tracked = source.replace("        u_out[i] = acc\n",
                             "        u_out[i] = acc + fc_torque(i, t, z, y, params)\n")
    if tracked == source:
        raise AssertionError("the tracker's source has no command to compensate")
    return (tracked + f"""

def fc_x(j, t, z, y, params):
    return {state}
""" + compensation.source(system))


def compensated_plan(system: System, comp: compensation.Compensation, traj: Trajectory,
                 xs: np.ndarray, us: np.ndarray) -> tuple[System, np.ndarray]:
    """The plant a compensated tracker's gains along the plan are designed for (*system*
    with the compensated frictions at zero) and the plan's feedforward on it: the plan's
    inputs less the friction torque the plan's own model needed along it (its parameters,
    *traj*'s where it records them: a plan made without friction needed none), which the
    compensation now supplies."""
    # Along the plan the friction left is linearized where the plan moves (the design's
    # secant is for the balance, at rest: build_request, design_system).
    designed = compensation.compensated_system(system, comp)
    if not comp.parameters:
        return designed, us
    planned = system.with_params(**{k: float(v) for k, v in traj.params.items()
                                    if k in system.params and k in comp.parameters})
    need = np.array([compensation.torque(planned, comp, x) for x in xs])
    return designed, us - need
