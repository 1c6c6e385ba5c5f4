"""The operating point of a compiled model: whether a pose holds still, the
equilibrium nearest the file's pose, and the motors' authority there."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.importers.mujoco_compiler import load_mujoco

if TYPE_CHECKING:
    import mujoco

    from equilibrist.importers.tree import ActuatorData


# The nearest equilibrium may lie at most this far from the file's pose, in
# each coordinate that moves (rad or m); farther, the file's pose is kept and
# the operating point is refused where it is used, saying what was found.
MAX_MOVE = 0.1


def _holds(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, qvel: np.ndarray,
           ctrl: np.ndarray) -> bool:
    """Whether *qpos*, *qvel* with the controls *ctrl* is an equilibrium (qacc = 0)."""
    mujoco = load_mujoco()
    data.qpos[:], data.qvel[:] = qpos, qvel
    if model.nu:
        data.ctrl[:] = ctrl
    mujoco.mj_forward(model, data)
    return bool(np.all(np.abs(data.qacc) < 1e-9 * (1.0 + np.abs(data.qfrc_bias).max(initial=0.0))))


def _nearest_equilibrium(
    model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray, qvel: np.ndarray,
    ctrl: np.ndarray, actuators: tuple[ActuatorData, ...], order: list[int], names: list[str],
) -> tuple[np.ndarray, np.ndarray, list[tuple[str, float]]]:
    """The equilibrium nearest the file's pose, by MuJoCo's inverse dynamics.

    The joints no actuator drives are free; at ``qacc = 0`` the generalized
    force that MuJoCo's ``mj_inverse`` asks for must vanish on them (solved
    from the file's pose, so the solution is the nearest one) and equal the
    motors' force on the driven joints (their controls solved by least
    squares). Returns the pose, the controls (in the actuators' order) and
    the coordinates that moved; a solution farther than :data:`MAX_MOVE`,
    or none, keeps the file's pose and controls.
    """
    from scipy.optimize import least_squares

    mujoco = load_mujoco()
    driven = {order[a.joint] for a in actuators}
    free = [j for j in range(model.njnt) if j not in driven]
    adr = [int(model.jnt_qposadr[j]) for j in free]
    dofs = [int(model.jnt_dofadr[j]) for j in free]

    def inverse(q: np.ndarray) -> np.ndarray:
        data.qpos[:], data.qvel[:] = q, qvel
        data.qacc[:] = 0.0
        mujoco.mj_inverse(model, data)
        return np.array(data.qfrc_inverse, float)

    q = qpos.copy()
    scale = 1.0 + float(np.abs(inverse(q)).max(initial=0.0))
    if free:
        def residual(z: np.ndarray) -> np.ndarray:
            qq = qpos.copy()
            qq[adr] = z
            return inverse(qq)[dofs] / scale

        with np.errstate(all="ignore"):
            z = least_squares(residual, qpos[adr], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        if not (np.all(np.isfinite(z)) and np.abs(z - qpos[adr]).max() <= MAX_MOVE
                and np.abs(residual(z)).max() <= 1e-12):
            return qpos, ctrl, []
        q[adr] = z
    force = inverse(q)
    new_ctrl = ctrl.copy()
    if actuators:
        gains = np.zeros((model.nv, len(actuators)))
        for k, a in enumerate(actuators):
            gains[int(model.jnt_dofadr[order[a.joint]]), k] = a.gain
        solved = np.linalg.lstsq(gains, force, rcond=None)[0]
        if len(new_ctrl) == len(actuators):
            new_ctrl = solved
    # Moves of round-off size (a joint the solver only grazed) are not reported.
    moved = [(names[j], float(q[a] - qpos[a])) for j, a in zip(free, adr, strict=True)
             if abs(q[a] - qpos[a]) > 1e-12]
    return q, new_ctrl, moved


def _authority(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray,
               actuators: tuple[ActuatorData, ...], order: list[int]) -> tuple[float, ...]:
    """Per joint (in *order*), ``sum_a |M^-1[j, a]| * |gain_a| * (high_a - low_a) / 2``."""
    mujoco = load_mujoco()
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    inverse = np.linalg.inv(mass)
    reach = np.zeros(model.nv)
    for a in actuators:
        dof = int(model.jnt_dofadr[order[a.joint]])
        reach += np.abs(inverse[:, dof]) * abs(a.gain) * (a.high - a.low) / 2
    return tuple(float(reach[int(model.jnt_dofadr[j])]) for j in order)


def _linearization(model: mujoco.MjModel, data: mujoco.MjData, qpos: np.ndarray,
                   qvel: np.ndarray, ctrl: np.ndarray, actuators: tuple[ActuatorData, ...],
                   order: list[int]
                   ) -> tuple[tuple[tuple[float, ...], ...], tuple[tuple[float, ...], ...]]:
    """``(A, B)`` of ``x_dot = f(x, u)`` at the operating point, by MuJoCo's forward
    dynamics (central differences): ``x`` the joints' positions then their rates (in
    *order*), ``u`` each motor's physical force or torque (``gain * ctrl``)."""
    mujoco = load_mujoco()
    n = len(order)
    adr = [int(model.jnt_qposadr[j]) for j in order]
    dof = [int(model.jnt_dofadr[j]) for j in order]

    def qacc(q: np.ndarray, v: np.ndarray) -> np.ndarray:
        data.qpos[:], data.qvel[:] = q, v
        if model.nu:
            data.ctrl[:] = ctrl
        mujoco.mj_forward(model, data)
        return np.array(data.qacc, float)[dof]

    a = np.zeros((2 * n, 2 * n))
    a[:n, n:] = np.eye(n)
    step = 1e-6
    for k in range(n):
        for block, base, index in ((0, qpos, adr[k]), (n, qvel, dof[k])):
            plus, minus = base.copy(), base.copy()
            plus[index] += step
            minus[index] -= step
            args = ((plus, qvel), (minus, qvel)) if block == 0 else ((qpos, plus), (qpos, minus))
            a[n:, block + k] = (qacc(*args[0]) - qacc(*args[1])) / (2 * step)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    inverse = np.linalg.inv(mass)
    b = np.zeros((2 * n, len(actuators)))
    for k, act in enumerate(actuators):
        b[n:, k] = inverse[np.ix_(dof, [dof[act.joint]])][:, 0]
    return (tuple(tuple(float(v) for v in row) for row in a),
            tuple(tuple(float(v) for v in row) for row in b))
