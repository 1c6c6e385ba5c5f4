"""Angular velocity from Euler angles and their rates, derived with quaternions.

Two sequences are supported, each with its angles named and ordered as the
gyroscope's coordinates (``SYSTEMS.md``, "Rotations"):

``"xyz"``
    ``q = Rx(theta) Ry(phi) Rz(psi)``; angles ``(theta, phi, psi)``.
``"zxz"``
    ``q = Rz(phi) Rx(theta) Rz(psi)``; angles ``(phi, theta, psi)``.

The product is read as intrinsic rotations (about the axes of the frame
rotated so far), so the rotation matrix maps body coordinates to space
coordinates: ``R = Rx(theta) @ Ry(phi) @ Rz(psi)``, which is scipy's
``Rotation.from_euler("XYZ", ...)`` (upper case: intrinsic).

Angular velocity is ``omega = 2 q* q_dot`` in body coordinates and
``omega = 2 q_dot q*`` in space coordinates (vector parts; the scalar parts
vanish for a unit quaternion). Both are linear in the rates,
``omega = E(angles) @ rates``; the columns of ``E`` are ``2 q* dq/d(angle)``
(resp. ``2 dq/d(angle) q*``), which is how seed 002 computes them.

Agreement with seed 002 ("Angular velocity and quaternion")
    The printed body rates for xyz and zxz and the space rates for xyz
    (with the seed's ``|omega|^2 = theta_dot^2 + phi_dot^2 + psi_dot^2 + 2
    theta_dot psi_dot sin(phi)``) are reproduced exactly. The seed prints
    the components of ``Rx(theta) Ry(phi) Rz(psi)`` as a quaternion with
    full angles (``cos(theta) cos(phi) cos(psi) - ...``) where the half
    angles ``theta/2, phi/2, psi/2`` are meant: an OCR or notation slip,
    the products themselves are right with half angles. The space rates of
    zxz are not printed in the seed; here they are
    ``[theta_dot cos(phi) + psi_dot sin(theta) sin(phi),
    theta_dot sin(phi) - psi_dot sin(theta) cos(phi),
    phi_dot + psi_dot cos(theta)]``.

The symbolic derivation takes about a second the first time a sequence is
asked for; its result is kept for the life of the process.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import numpy as np
import sympy as sp
from sympy.algebras.quaternion import Quaternion
from sympy.simplify.fu import TR8

from equilibrist.errors import DimensionError, UnknownNameError, nearest

SEQUENCES: tuple[str, ...] = ("xyz", "zxz")
FRAMES: tuple[str, ...] = ("body", "space")

_ANGLE_NAMES = {"xyz": ("theta", "phi", "psi"), "zxz": ("phi", "theta", "psi")}


def _check_sequence(sequence: str) -> str:
    if sequence not in SEQUENCES:
        raise UnknownNameError(
            f"unknown Euler sequence {sequence!r}: {nearest(str(sequence), SEQUENCES)}"
        )
    return sequence


def _check_frame(frame: str) -> str:
    if frame not in FRAMES:
        raise UnknownNameError(
            f"unknown frame {frame!r} for the angular velocity: expected 'body' or 'space'"
        )
    return frame


def angle_names(sequence: str) -> tuple[str, str, str]:
    """Names of the three angles of *sequence*, in the order of the product.

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.

    Returns
    -------
    tuple of str
        ``("theta", "phi", "psi")`` for xyz, ``("phi", "theta", "psi")`` for zxz.
    """
    return _ANGLE_NAMES[_check_sequence(sequence)]


def angle_symbols(sequence: str) -> tuple[tuple[sp.Symbol, ...], tuple[sp.Symbol, ...]]:
    """The real symbols of the angles and of their rates (``<angle>_dot``).

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.

    Returns
    -------
    angles, rates : tuple of sympy.Symbol
        In the order of the product.
    """
    names = angle_names(sequence)
    angles = tuple(sp.Symbol(n, real=True) for n in names)
    rates = tuple(sp.Symbol(f"{n}_dot", real=True) for n in names)
    return angles, rates


def axis_quaternion(axis: str, angle: sp.Expr) -> Quaternion:
    """The unit quaternion of a rotation by *angle* about the coordinate *axis*.

    Parameters
    ----------
    axis : {"x", "y", "z"}
        Rotation axis.
    angle : sympy expression
        Rotation angle, counter-clockwise about the axis.

    Returns
    -------
    sympy.algebras.quaternion.Quaternion
        ``cos(angle/2) + sin(angle/2) * axis``.
    """
    if axis not in ("x", "y", "z"):
        raise UnknownNameError(f"unknown rotation axis {axis!r}: expected 'x', 'y' or 'z'")
    vector = [sp.Integer(0)] * 3
    vector["xyz".index(axis)] = sp.sin(angle / 2)
    return Quaternion(sp.cos(angle / 2), *vector)


def euler_quaternion(sequence: str, angles: tuple[sp.Expr, sp.Expr, sp.Expr]) -> Quaternion:
    """The quaternion ``q`` of the Euler *sequence* at *angles* (product order).

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.
    angles : tuple of three sympy expressions
        Angles in the order of the product (see :func:`angle_names`).

    Returns
    -------
    sympy.algebras.quaternion.Quaternion
        ``q1 * q2 * q3`` with ``qi`` the rotation about the i-th axis of *sequence*.
    """
    _check_sequence(sequence)
    if len(angles) != 3:
        raise DimensionError(f"an Euler sequence has 3 angles, got {len(angles)}")
    q = axis_quaternion(sequence[0], angles[0])
    for axis, angle in zip(sequence[1:], angles[1:], strict=True):
        q = q * axis_quaternion(axis, angle)
    return q


def _to_full_angles(expr: sp.Expr) -> sp.Expr:
    # Every entry is a sum of products of two half-angle sines/cosines:
    # product-to-sum (TR8) turns them into full-angle terms, which
    # expand_trig then writes back as products of full-angle sines/cosines.
    return sp.simplify(sp.expand_trig(TR8(sp.expand(expr))))


@cache
def angular_velocity_matrix_expr(sequence: str, *, frame: str = "body") -> sp.ImmutableMatrix:
    """Symbolic ``E(angles)`` with ``omega = E @ rates``.

    Column ``i`` is the vector part of ``2 q* dq/d(angle_i)`` (body frame) or
    ``2 dq/d(angle_i) q*`` (space frame).

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.
    frame : {"body", "space"}
        Coordinates in which ``omega`` is written.

    Returns
    -------
    sympy.ImmutableMatrix
        3 x 3, in the symbols of :func:`angle_symbols`.
    """
    _check_sequence(sequence)
    _check_frame(frame)
    angles, _ = angle_symbols(sequence)
    q = euler_quaternion(sequence, angles)
    columns = []
    for angle in angles:
        dq = sp.diff(q, angle)
        w = 2 * q.conjugate() * dq if frame == "body" else 2 * dq * q.conjugate()
        scalar = _to_full_angles(w.a)
        if scalar != 0:  # a unit quaternion's q* dq is a pure vector
            raise ArithmeticError(f"scalar part {scalar} of 2 q* dq is not zero")
        columns.append([_to_full_angles(c) for c in (w.b, w.c, w.d)])
    return sp.ImmutableMatrix(columns).T


def angular_velocity_expr(sequence: str, *, frame: str = "body") -> sp.ImmutableMatrix:
    """Symbolic angular velocity ``omega`` (3 x 1) in angles and rates.

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.
    frame : {"body", "space"}
        Coordinates in which ``omega`` is written.

    Returns
    -------
    sympy.ImmutableMatrix
        ``E(angles) @ rates`` in the symbols of :func:`angle_symbols`.
    """
    _, rates = angle_symbols(sequence)
    return sp.ImmutableMatrix(angular_velocity_matrix_expr(sequence, frame=frame) * sp.Matrix(rates))


@cache
def _matrix_function(sequence: str, frame: str) -> Callable[..., list[object]]:
    angles, _ = angle_symbols(sequence)
    entries = list(angular_velocity_matrix_expr(sequence, frame=frame))
    function: Callable[..., list[object]] = sp.lambdify(angles, entries, modules="numpy")
    return function


def _as_triples(values: object, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise DimensionError(f"{what} must have 3 values in its last axis, got shape {arr.shape}")
    return arr


def angular_velocity_matrix(sequence: str, angles: object, *, frame: str = "body") -> np.ndarray:
    """Numeric ``E(angles)`` with ``omega = E @ rates``.

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.
    angles : array_like, shape (..., 3)
        Angles in the order of the product [rad].
    frame : {"body", "space"}
        Coordinates in which ``omega`` is written.

    Returns
    -------
    numpy.ndarray, shape (..., 3, 3)
    """
    _check_sequence(sequence)
    _check_frame(frame)
    arr = _as_triples(angles, "angles")
    entries = _matrix_function(sequence, frame)(arr[..., 0], arr[..., 1], arr[..., 2])
    batch = arr.shape[:-1]
    # Constant entries come back as Python scalars: give them the batch shape.
    stacked = np.stack([np.broadcast_to(np.asarray(e, dtype=float), batch) for e in entries], -1)
    return stacked.reshape(*batch, 3, 3)


def angular_velocity(
    sequence: str, angles: object, rates: object, *, frame: str = "body"
) -> np.ndarray:
    """Angular velocity from Euler angles and their rates.

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.
    angles, rates : array_like, shape (..., 3)
        Angles [rad] and their rates [rad/s], in the order of the product
        (:func:`angle_names`).
    frame : {"body", "space"}
        ``"body"``: components along the rotated (body) axes, ``2 q* q_dot``;
        ``"space"``: components along the fixed axes, ``2 q_dot q*``.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        ``omega`` [rad/s].
    """
    E = angular_velocity_matrix(sequence, angles, frame=frame)
    r = _as_triples(rates, "rates")
    omega: np.ndarray = np.einsum("...ij,...j->...i", E, r)
    return omega


def rotation_matrix(sequence: str, angles: object) -> np.ndarray:
    """Rotation matrix ``R`` (body to space coordinates) of the Euler *sequence*.

    Parameters
    ----------
    sequence : {"xyz", "zxz"}
        The Euler sequence.
    angles : array_like, shape (3,)
        Angles in the order of the product [rad].

    Returns
    -------
    numpy.ndarray, shape (3, 3)
        The product of the elementary rotations, e.g. ``Rx @ Ry @ Rz``.
    """
    _check_sequence(sequence)
    arr = _as_triples(angles, "angles")
    if arr.ndim != 1:
        raise DimensionError(f"rotation_matrix takes one set of angles, got shape {arr.shape}")
    out = np.eye(3)
    for axis, angle in zip(sequence, arr, strict=True):
        out = out @ _elementary(axis, float(angle))
    return out


def _elementary(axis: str, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    if axis == "x":
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    if axis == "y":
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
