"""Tools for the gyroscope family: steady precession, changes of parameterization.

(The leading underscore keeps the registry from importing this module as a
system.)

Steady precession
    With the nutation angle held (``theta_dot = 0``), the zxz equations of
    the heavy symmetric top give ``phi_ddot = psi_ddot = 0`` (their
    right-hand sides are proportional to ``theta_dot``), and the nutation
    equation ``theta_ddot = 0`` reads, after division by ``sin(theta)``::

        I_c cos(theta) phi_dot^2 + I_z psi_dot phi_dot - p = 0

    with ``I_c = I_s - (I_t + m R^2)``, ``I_z = I_s``, ``p = m g R``: seed
    002's relation. :func:`steady_precession_relation` derives it from the
    registered model's ``f``; :func:`steady_precession_rates` solves it.
    Its two roots are the slow precession (smaller ``|phi_dot|``; about
    ``p / (I_z psi_dot)`` for a fast top) and the fast one (about
    ``-I_z psi_dot / (I_c cos(theta))``).

Changing parameterization
    :func:`zxz_to_xyz` and :func:`xyz_to_zxz` map a state of one variant to
    the state of the other with the same orientation of the wheel and the
    same angular velocity: the same physical motion from then on. The
    orientation goes through its rotation matrix, the rates through the
    body angular velocity ``omega = E(angles) @ rates`` of
    :mod:`equilibrist.mechanics.rotations`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import (
    DimensionError,
    NoEquilibriumError,
    ParameterError,
    SingularConfigurationError,
    UnknownNameError,
    finite_number,
)

if TYPE_CHECKING:  # sympy is imported only by the functions that need it
    import sympy as sp

    from equilibrist.mechanics.model import SymbolicModel
    from equilibrist.numeric.system import System

# |sin(theta)| (zxz) or |cos(phi)| (xyz) below which a conversion counts as
# singular: there the angle pair about the common line is not defined.
_SINGULAR = 1e-9


class NoSteadyPrecessionError(NoEquilibriumError):
    """No real steady-precession rate exists for the nutation angle and spin asked for."""


def _check_gyroscope(system: System) -> None:
    if system.spec.name != "gyroscope":
        raise UnknownNameError(
            f"steady precession is defined for the gyroscope, not for {system.key}"
        )




def steady_precession_relation(model: SymbolicModel) -> sp.Expr:
    """The steady-precession condition, derived from the zxz model's ``f``.

    Sets ``theta_dot = 0`` in the nutation equation ``theta_ddot = f(x)``
    of the zxz model and keeps its numerator, divided by ``sin(theta)``
    (the factor that vanishes at the parameterization's singularity) and
    normalized to make the constant term ``-m g R``.

    Parameters
    ----------
    model : SymbolicModel
        The symbolic model of ``gyroscope[euler=zxz]``
        (``get_system("gyroscope").symbolic``).

    Returns
    -------
    sympy.Expr
        An expression in ``theta, phi_dot, psi_dot`` and the parameters
        that vanishes exactly at steady precession; equal to the seed's
        ``I_c phi_dot^2 cos(theta) + I_z psi_dot phi_dot - p``.
    """
    import sympy as sp
    if model.spec_key != "gyroscope[euler=zxz]":
        raise UnknownNameError(
            f"the steady-precession relation is derived from gyroscope[euler=zxz], "
            f"not from {model.spec_key}"
        )
    names = [s.name for s in model.states]
    theta = model.states[names.index("theta")]
    theta_dot = model.states[names.index("theta_dot")]
    by_name = {s.name: s for s in model.params}
    m, g, R = by_name["m"], by_name["g"], by_name["R"]
    nutation = model.f[names.index("theta_dot")].subs(theta_dot, 0)
    numerator, _ = sp.fraction(sp.cancel(sp.together(nutation)))
    reduced = sp.cancel(sp.expand_trig(numerator) / sp.sin(theta))
    constant = reduced.subs({s: 0 for s in model.states if s.name.endswith("_dot")})
    # Normalizing by the constant term fixes both the scale and the sign.
    return sp.expand(sp.simplify(-m * g * R * reduced / constant))


def steady_precession_rates(system: System, theta: float, psi_dot: float) -> tuple[float, float]:
    """The slow and fast steady-precession rates of the heavy top.

    Solves ``I_c cos(theta) phi_dot^2 + I_z psi_dot phi_dot = p`` (see the
    module docstring) for the precession rate ``phi_dot``.

    Parameters
    ----------
    system : System
        A gyroscope (either variant: only its parameters are used).
    theta : float
        Nutation angle, the tilt of the axis from vertical-up [rad]
        (zxz's ``theta``).
    psi_dot : float
        Spin, the zxz Euler rate ``psi_dot`` [rad/s] (not the total spin).

    Returns
    -------
    slow, fast : float
        The two roots ``phi_dot`` [rad/s], zxz precession rates, ordered by
        magnitude (``|slow| <= |fast|``). With ``theta``, ``theta_dot = 0``,
        ``phi_dot`` and ``psi_dot`` as the zxz state the top precesses
        steadily. Use :func:`zxz_to_xyz` for the xyz variant.

    Raises
    ------
    SingularConfigurationError
        Where ``sin(theta) = 0``: the axis is vertical and precession is
        not defined.
    NoSteadyPrecessionError
        When the relation has no real root (spin too slow for the tilt),
        or only one, when ``I_c cos(theta) = 0`` exactly (the fast root
        escapes to infinity).
    """
    _check_gyroscope(system)
    theta = finite_number("theta", theta)
    psi_dot = finite_number("psi_dot", psi_dot)
    if abs(math.sin(theta)) < _SINGULAR:
        raise SingularConfigurationError(
            f"steady precession at theta = {theta:g}: the axis is vertical (sin(theta) = 0), "
            "where the precession rate is not defined"
        )
    prm = system.params
    I_xy = prm["I_t"] + prm["m"] * prm["R"] ** 2
    I_z = prm["I_s"]
    p = prm["m"] * prm["g"] * prm["R"]
    a = (I_z - I_xy) * math.cos(theta)
    b = I_z * psi_dot
    c = -p
    discriminant = b * b - 4.0 * a * c
    if discriminant < 0.0:
        # Only possible with a < 0 (the axis above horizontal, I_c < 0).
        slowest = 2.0 * math.sqrt(-a * p) / I_z
        raise NoSteadyPrecessionError(
            f"no steady precession of {system.key} at theta = {theta:g} rad with psi_dot = "
            f"{psi_dot:g} rad/s: I_c cos(theta) phi_dot^2 + I_z psi_dot phi_dot = p has no real "
            f"root (it needs |psi_dot| >= {slowest:.6g} rad/s at this tilt)"
        )
    # cos(pi/2) is 6e-17 in floating point: a horizontal axis counts as
    # cos(theta) = 0 (the fast root runs off to 1e17 rad/s otherwise).
    if abs(math.cos(theta)) < 1e-9 or a == 0.0:
        raise NoSteadyPrecessionError(
            f"I_c cos(theta) = 0 at theta = {theta:g} rad: the relation is linear, its only root "
            f"is the slow precession phi_dot = p / (I_z psi_dot) = {p / b:.6g} rad/s"
            if b != 0.0
            else f"no steady precession at theta = {theta:g} rad without spin"
        )
    # The stable form of the quadratic formula: no cancellation in either root.
    q = -0.5 * (b + math.copysign(math.sqrt(discriminant), b))
    roots = sorted((c / q, q / a), key=abs)
    return roots[0], roots[1]


def _state(x: object, what: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.shape != (6,):
        raise DimensionError(f"{what} must have 6 values, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{what} has a value that is not a finite number: {arr.tolist()}")
    return arr


def spin_axis(euler: str, x: object) -> np.ndarray:
    """Unit vector of the wheel's axis in the room frame (z up).

    Parameters
    ----------
    euler : {"zxz", "xyz"}
        The variant whose states *x* are.
    x : array_like, shape (..., 6) or (..., 3)
        States (or just the three angles), in the variant's order.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        The third column of the rotation matrix: zxz ``(sin(phi) sin(theta),
        -cos(phi) sin(theta), cos(theta))``; xyz ``(sin(phi),
        -cos(phi) sin(theta), cos(phi) cos(theta))``.
    """
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] not in (3, 6):
        raise DimensionError(f"spin_axis needs states or angles in the last axis, got {arr.shape}")
    if euler == "zxz":
        phi, theta = arr[..., 0], arr[..., 1]
        return np.stack(
            [np.sin(phi) * np.sin(theta), -np.cos(phi) * np.sin(theta), np.cos(theta)], -1
        )
    if euler == "xyz":
        theta, phi = arr[..., 0], arr[..., 1]
        return np.stack(
            [np.sin(phi), -np.cos(phi) * np.sin(theta), np.cos(phi) * np.cos(theta)], -1
        )
    raise UnknownNameError(f"euler = {euler!r} is not a variant of gyroscope: expected zxz or xyz")


def zxz_to_xyz(x: object) -> np.ndarray:
    """The xyz state with the same orientation and angular velocity as zxz state *x*.

    Parameters
    ----------
    x : array_like, shape (6,)
        ``[phi, theta, psi, phi_dot, theta_dot, psi_dot]`` (zxz).

    Returns
    -------
    numpy.ndarray, shape (6,)
        ``[theta, phi, psi, theta_dot, phi_dot, psi_dot]`` (xyz), with
        ``phi`` in ``[-pi/2, pi/2]`` and the other angles in ``(-pi, pi]``.

    Raises
    ------
    SingularConfigurationError
        If the orientation has ``cos(phi) = 0`` in xyz angles (axis
        horizontal along the room's x axis) or *x* is itself singular in
        zxz (``sin(theta) = 0``): the rates are not defined there.
    """
    from equilibrist.mechanics import rotations

    xv = _state(x, "the zxz state")
    if abs(math.sin(xv[1])) < _SINGULAR:
        raise SingularConfigurationError(
            f"zxz state at theta = {xv[1]:g} is singular (sin(theta) = 0): its rates do not "
            "define an angular velocity uniquely"
        )
    R = rotations.rotation_matrix("zxz", xv[:3])
    sin_phi = float(np.clip(R[0, 2], -1.0, 1.0))
    cos_phi = math.sqrt(max(0.0, 1.0 - sin_phi * sin_phi))
    if cos_phi < _SINGULAR:
        raise SingularConfigurationError(
            "this orientation is singular in xyz angles (cos(phi) = 0: the axis is horizontal "
            "along the room's x axis)"
        )
    angles = np.array(
        [math.atan2(-R[1, 2], R[2, 2]), math.asin(sin_phi), math.atan2(-R[0, 1], R[0, 0])]
    )
    return np.concatenate([angles, _rates_for(xv, "zxz", angles, "xyz")])


def xyz_to_zxz(x: object) -> np.ndarray:
    """The zxz state with the same orientation and angular velocity as xyz state *x*.

    Parameters
    ----------
    x : array_like, shape (6,)
        ``[theta, phi, psi, theta_dot, phi_dot, psi_dot]`` (xyz).

    Returns
    -------
    numpy.ndarray, shape (6,)
        ``[phi, theta, psi, phi_dot, theta_dot, psi_dot]`` (zxz), with
        ``theta`` in ``[0, pi]`` and the other angles in ``(-pi, pi]``.

    Raises
    ------
    SingularConfigurationError
        If the axis is vertical (``sin(theta) = 0`` in zxz angles) or *x*
        is itself singular in xyz (``cos(phi) = 0``).
    """
    from equilibrist.mechanics import rotations

    xv = _state(x, "the xyz state")
    if abs(math.cos(xv[1])) < _SINGULAR:
        raise SingularConfigurationError(
            f"xyz state at phi = {xv[1]:g} is singular (cos(phi) = 0): its rates do not "
            "define an angular velocity uniquely"
        )
    R = rotations.rotation_matrix("xyz", xv[:3])
    cos_theta = float(np.clip(R[2, 2], -1.0, 1.0))
    if math.sqrt(max(0.0, 1.0 - cos_theta * cos_theta)) < _SINGULAR:
        raise SingularConfigurationError(
            "this orientation is singular in zxz angles (sin(theta) = 0: the axis is vertical)"
        )
    angles = np.array(
        [math.atan2(R[0, 2], -R[1, 2]), math.acos(cos_theta), math.atan2(R[2, 0], R[2, 1])]
    )
    return np.concatenate([angles, _rates_for(xv, "xyz", angles, "zxz")])


def _rates_for(x: np.ndarray, source: str, angles: np.ndarray, target: str) -> np.ndarray:
    from equilibrist.mechanics import rotations

    # Same rotation matrix, so the same body frame: equal body angular
    # velocities mean the same motion.
    omega = rotations.angular_velocity(source, x[:3], x[3:], frame="body")
    E = rotations.angular_velocity_matrix(target, angles, frame="body")
    return np.linalg.solve(E, omega)
