"""The four-bar linkage between a servo and the ball-balancing platform.

Kinematics only (``SYSTEMS.md``, "four-bar linkage"; seeds/002 "Ball
rolling on a platform inverse kinetic"). In the plane of the linkage:

* the motor axis ``M`` is at ``(-a, 0)``; the motor arm, of length ``d``,
  makes the motor angle ``theta`` with +x, its tip at
  ``T = (d cos(theta) - a, d sin(theta))``;
* the platform pivot ``P`` is at ``(0, b)``; the platform hinge, at
  distance ``c`` from it, makes the platform angle ``phi`` with +x, at
  ``H = (c cos(phi), b + c sin(phi))``;
* the coupler of length ``e`` joins ``T`` and ``H``. Loop closure::

      (d cos(theta) - c cos(phi) - a)^2 + (d sin(theta) - c sin(phi) - b)^2 = e^2

Both angles are counter-clockwise from +x, in radians.

Assembly branches
    Solving for one angle from the other places a moving joint on the
    intersection of two circles: two solutions. They are named after the
    side of a ray on which the moving joint lies, looking from the fixed
    pivot of the angle being solved for to the tip of the other link:

    * :meth:`FourBar.platform_angle` (``phi`` from ``theta``): the hinge
      ``H`` is counter-clockwise (``"plus"``) or clockwise (``"minus"``)
      of the ray from ``P`` to the arm tip ``T``.
    * :meth:`FourBar.motor_angle` (``theta`` from ``phi``): the arm tip
      ``T`` is counter-clockwise (``"plus"``) or clockwise (``"minus"``)
      of the ray from ``M`` to the hinge ``H``.

    The two directions split the poses differently. In the usual rig, arm
    and platform nearly parallel (the seed's near-parallelogram, motor
    below and left of the pivot), the working pose is ``"plus"`` for
    :meth:`~FourBar.platform_angle` and ``"minus"`` for
    :meth:`~FourBar.motor_angle` (their defaults); the other branch is
    the crossed pose. A pose keeps its name along a continuous motion
    until the two branches meet, where the moving joint lies on the ray
    (the coupler in line with a link: a dead point, or, in the exact
    parallelogram, the flat pose at ``theta = phi = atan2(b, a)``).

The seed's closed form (an approximation)
    Expanding the closure gives ``-2 c d cos(theta - phi)``; the seed
    writes ``-2 c d``, i.e. ``cos(theta - phi) = 1``, exact only when arm
    and platform are parallel (as in the parallelogram ``c = d, a = b,
    e = sqrt(2) b``, where ``theta = phi``). With
    ``f = a^2 + b^2 - e^2 + (c - d)^2`` it reads
    ``a cos(theta) + b sin(theta) = (c/d)(a cos(phi) + b sin(phi)) + f/(2d)``,
    solved in :meth:`FourBar.approximate_motor_angle` and
    :meth:`FourBar.approximate_platform_angle`. Its two roots are mirror
    images about the line through the fixed pivots, so the approximate
    branches are named by the side of the ray from the solved angle's
    fixed pivot towards the other fixed pivot (the exact rule with the
    other link's tip replaced by its pivot); on the usual rig they pick
    the same poses as the exact names. The error of the approximation
    grows with ``|theta - phi|``. On the generic geometries of the tests
    it stays below 0.015 rad over a platform tilt of +-0.3 rad (within the
    0.25 rad of SYSTEMS.md), but towards the reach limits it passes
    0.4 rad, and there the approximation may have no solution where the
    linkage has one (or the reverse).

Seed slips
    The seed's ``cos(phi)``, ``sin(phi)`` formulas write ``g`` where ``h``
    is meant. Its printed rate ``theta_dot = -(c - a sin(phi) + b cos(phi))
    / sqrt(a^2 + b^2 - g^2) phi_dot`` is wrong; differentiating its own
    approximate relation gives ``theta_dot = +-(c/d)(-a sin(phi) +
    b cos(phi)) / sqrt(a^2 + b^2 - g^2) phi_dot``
    (:meth:`FourBar.approximate_rate_ratio`). The exact ratio is
    :meth:`FourBar.rate_ratio`. In the special case ``c = d, a = b,
    e = sqrt(2) b`` the seed finds ``theta_dot = +-phi_dot``: ``+`` is
    exact (the parallelogram, ``theta = phi``); ``-`` belongs to the
    approximation's spurious root ``theta = pi/2 - phi``, which is not a
    pose of the linkage (the crossed pose is another curve).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from equilibrist.errors import EquilibristError, ParameterError, SingularConfigurationError

BRANCHES: tuple[str, ...] = ("plus", "minus")

# Relative tolerance of the loop closure for a pose handed in by the caller.
_CLOSURE_TOLERANCE = 1e-9


class UnreachablePoseError(EquilibristError, ValueError):
    """A linkage pose that cannot be assembled (the coupler is too short or too long)."""


def _branch_sign(branch: str) -> float:
    if branch == "plus":
        return 1.0
    if branch == "minus":
        return -1.0
    raise ParameterError(f"branch = {branch!r} is not an assembly branch: expected 'plus' or 'minus'")


def _angles(values: object, name: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} = {values!r} is not a number") from None
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} has a value that is not a finite number: {arr.tolist()}")
    return arr


def _out(arr: np.ndarray) -> float | np.ndarray:
    return float(arr) if arr.ndim == 0 else arr


@dataclass(frozen=True)
class FourBar:
    """A four-bar linkage of the ball-balancing platform (lengths in metres).

    Parameters
    ----------
    a : float
        Horizontal offset of the motor axis, which is at ``(-a, 0)``.
    b : float
        Height of the platform pivot, which is at ``(0, b)``.
    c : float
        Platform pivot to platform hinge, > 0.
    d : float
        Motor arm length, > 0.
    e : float
        Coupler length, > 0.

    Raises
    ------
    ParameterError
        Naming every length that is not finite or not positive, or the
        fixed pivots coinciding (``a = b = 0``).
    """

    a: float
    b: float
    c: float
    d: float
    e: float

    def __post_init__(self) -> None:
        problems = []
        for name in ("a", "b", "c", "d", "e"):
            value = getattr(self, name)
            try:
                v = float(value)
            except (TypeError, ValueError):
                problems.append(f"{name} = {value!r} is not a number")
                continue
            if not math.isfinite(v):
                problems.append(f"{name} = {v} is not a finite number")
            elif name in ("c", "d", "e") and v <= 0.0:
                problems.append(f"{name} = {v:g} is out of range: expected a length in (0, inf)")
            else:
                object.__setattr__(self, name, v)
        if not problems and self.a == 0.0 and self.b == 0.0:
            problems.append("a = b = 0 puts the motor axis on the platform pivot")
        if problems:
            raise ParameterError("four-bar linkage: " + "; ".join(problems))

    # -- geometry ----------------------------------------------------------------
    @property
    def motor_axis(self) -> tuple[float, float]:
        """``M = (-a, 0)``."""
        return (-self.a, 0.0)

    @property
    def platform_pivot(self) -> tuple[float, float]:
        """``P = (0, b)``."""
        return (0.0, self.b)

    def arm_tip(self, theta: object) -> np.ndarray:
        """Motor arm tip ``T = (d cos(theta) - a, d sin(theta))``, shape ``(..., 2)``."""
        th = _angles(theta, "theta")
        return np.stack([self.d * np.cos(th) - self.a, self.d * np.sin(th)], -1)

    def hinge(self, phi: object) -> np.ndarray:
        """Platform hinge ``H = (c cos(phi), b + c sin(phi))``, shape ``(..., 2)``."""
        ph = _angles(phi, "phi")
        return np.stack([self.c * np.cos(ph), self.b + self.c * np.sin(ph)], -1)

    def closure_residual(self, theta: object, phi: object) -> float | np.ndarray:
        """``|T - H| - e`` [m]: zero at an assembled pose.

        Parameters
        ----------
        theta, phi : float or array_like
            Motor and platform angles [rad].

        Returns
        -------
        float or numpy.ndarray
        """
        gap = self.arm_tip(theta) - self.hinge(phi)
        return _out(np.hypot(gap[..., 0], gap[..., 1]) - self.e)

    # -- exact loop closure --------------------------------------------------------
    def platform_angle(self, theta: object, *, branch: str = "plus") -> float | np.ndarray:
        """Platform angle ``phi`` for the motor angle *theta* (exact).

        Parameters
        ----------
        theta : float or array_like
            Motor angle [rad].
        branch : {"plus", "minus"}
            ``"plus"``: the hinge counter-clockwise of the ray from the
            platform pivot to the arm tip (the usual, uncrossed pose);
            ``"minus"``: clockwise.

        Returns
        -------
        float or numpy.ndarray
            ``phi`` in ``(-pi, pi]`` [rad].

        Raises
        ------
        UnreachablePoseError
            If the coupler cannot span from the arm tip to the platform's
            hinge circle for some *theta*.
        """
        sign = _branch_sign(branch)
        tip = self.arm_tip(theta)
        joint = _circle_intersection(
            np.array(self.platform_pivot), self.c, tip, self.e, sign,
            what="motor angle", angles=_angles(theta, "theta"),
        )
        return _out(np.arctan2(joint[..., 1] - self.b, joint[..., 0]))

    def motor_angle(self, phi: object, *, branch: str = "minus") -> float | np.ndarray:
        """Motor angle ``theta`` for the platform angle *phi* (exact).

        Parameters
        ----------
        phi : float or array_like
            Platform angle [rad].
        branch : {"plus", "minus"}
            ``"plus"``: the arm tip counter-clockwise of the ray from the
            motor axis to the hinge; ``"minus"``: clockwise (the usual,
            uncrossed pose, hence the default).

        Returns
        -------
        float or numpy.ndarray
            ``theta`` in ``(-pi, pi]`` [rad].

        Raises
        ------
        UnreachablePoseError
            If the coupler cannot span from the hinge to the arm's circle
            for some *phi*.
        """
        sign = _branch_sign(branch)
        hinge = self.hinge(phi)
        joint = _circle_intersection(
            np.array(self.motor_axis), self.d, hinge, self.e, sign,
            what="platform angle", angles=_angles(phi, "phi"),
        )
        return _out(np.arctan2(joint[..., 1], joint[..., 0] + self.a))

    def rate_ratio(self, theta: object, phi: object) -> float | np.ndarray:
        """``d theta / d phi`` at the assembled pose ``(theta, phi)`` (exact).

        From the derivative of the loop closure ``|T - H|^2 = e^2``:
        ``d theta / d phi = ((T - H) . dH/dphi) / ((T - H) . dT/dtheta)``.

        Parameters
        ----------
        theta, phi : float or array_like
            An assembled pose (e.g. ``phi`` and ``motor_angle(phi)``).

        Returns
        -------
        float or numpy.ndarray
            The motor rate per unit platform rate.

        Raises
        ------
        UnreachablePoseError
            If ``(theta, phi)`` does not close the loop.
        SingularConfigurationError
            At a dead point of the motor (coupler in line with the motor
            arm), where the motor angle is at an extreme and the ratio is
            infinite.
        """
        th, ph = np.broadcast_arrays(_angles(theta, "theta"), _angles(phi, "phi"))
        residual = np.abs(np.asarray(self.closure_residual(th, ph)))
        scale = self.e + self.d + self.c + math.hypot(self.a, self.b)
        if np.any(residual > _CLOSURE_TOLERANCE * scale):
            worst = int(np.argmax(residual))
            raise UnreachablePoseError(
                f"theta = {th.flat[worst]:g}, phi = {ph.flat[worst]:g} is not a pose of this "
                f"linkage: the loop does not close (|T - H| - e = {residual.flat[worst]:.3g} m)"
            )
        gap = self.arm_tip(th) - self.hinge(ph)
        d_tip = self.d * np.stack([-np.sin(th), np.cos(th)], -1)
        d_hinge = self.c * np.stack([-np.sin(ph), np.cos(ph)], -1)
        numerator = np.sum(gap * d_hinge, -1)
        denominator = np.sum(gap * d_tip, -1)
        if np.any(np.abs(denominator) <= 1e-12 * self.e * self.d):
            raise SingularConfigurationError(
                "the coupler is in line with the motor arm (a dead point): d theta / d phi is "
                "infinite there"
            )
        return _out(numerator / denominator)

    # -- the seed's approximation ---------------------------------------------------
    @property
    def f(self) -> float:
        """The seed's constant ``f = a^2 + b^2 - e^2 + (c - d)^2``."""
        return self.a**2 + self.b**2 - self.e**2 + (self.c - self.d) ** 2

    def approximate_motor_angle(self, phi: object, *, branch: str = "minus") -> float | np.ndarray:
        """The seed's closed form for ``theta`` (``cos(theta - phi)`` taken as 1).

        Solves ``a cos(theta) + b sin(theta) = g`` with
        ``g = (c/d)(a cos(phi) + b sin(phi)) + f/(2d)``:
        ``cos(theta) = (a g -+ b s) / (a^2 + b^2)``,
        ``sin(theta) = (b g +- a s) / (a^2 + b^2)``, ``s = sqrt(a^2 + b^2 - g^2)``.

        Parameters
        ----------
        phi : float or array_like
            Platform angle [rad].
        branch : {"plus", "minus"}
            ``"plus"``: the arm counter-clockwise of the ray from the motor
            axis to the platform pivot (the seed's lower signs);
            ``"minus"``: clockwise (the seed's upper signs, the usual pose).

        Returns
        -------
        float or numpy.ndarray
            Approximate ``theta`` [rad].

        Raises
        ------
        UnreachablePoseError
            Where ``|g| > sqrt(a^2 + b^2)``.
        """
        sign = _branch_sign(branch)
        ph = _angles(phi, "phi")
        g = (self.c / self.d) * (self.a * np.cos(ph) + self.b * np.sin(ph)) + self.f / (2 * self.d)
        return _out(self._solve_projection(g, -sign, ph, "platform angle"))

    def approximate_platform_angle(
        self, theta: object, *, branch: str = "plus"
    ) -> float | np.ndarray:
        """The seed's closed form for ``phi`` (``cos(theta - phi)`` taken as 1).

        Solves ``a cos(phi) + b sin(phi) = h`` with
        ``h = (d/c)(a cos(theta) + b sin(theta)) - f/(2c)`` (the seed writes
        ``g`` for ``h`` in the solution: a slip).

        Parameters
        ----------
        theta : float or array_like
            Motor angle [rad].
        branch : {"plus", "minus"}
            ``"plus"``: the platform counter-clockwise of the ray from the
            platform pivot towards the motor axis (the seed's upper signs,
            the usual pose); ``"minus"``: clockwise.

        Returns
        -------
        float or numpy.ndarray
            Approximate ``phi`` [rad].

        Raises
        ------
        UnreachablePoseError
            Where ``|h| > sqrt(a^2 + b^2)``.
        """
        sign = _branch_sign(branch)
        th = _angles(theta, "theta")
        h = (self.d / self.c) * (self.a * np.cos(th) + self.b * np.sin(th)) - self.f / (2 * self.c)
        return _out(self._solve_projection(h, sign, th, "motor angle"))

    def approximate_rate_ratio(self, phi: object, *, branch: str = "minus") -> float | np.ndarray:
        """``d theta / d phi`` of :meth:`approximate_motor_angle` (corrected seed formula).

        ``+-(c/d)(-a sin(phi) + b cos(phi)) / sqrt(a^2 + b^2 - g^2)``, the
        upper sign for ``branch="minus"``.

        Parameters
        ----------
        phi : float or array_like
            Platform angle [rad].
        branch : {"plus", "minus"}
            As :meth:`approximate_motor_angle`.

        Returns
        -------
        float or numpy.ndarray
        """
        sign = _branch_sign(branch)
        ph = _angles(phi, "phi")
        g = (self.c / self.d) * (self.a * np.cos(ph) + self.b * np.sin(ph)) + self.f / (2 * self.d)
        s = self._root(g, ph, "platform angle")
        if np.any(s == 0.0):
            raise SingularConfigurationError(
                "the approximate relation is at its extreme (a^2 + b^2 = g^2): its rate is infinite"
            )
        return _out(-sign * (self.c / self.d) * (-self.a * np.sin(ph) + self.b * np.cos(ph)) / s)

    def _root(self, value: np.ndarray, given: np.ndarray, what: str) -> np.ndarray:
        room = self.a**2 + self.b**2 - value**2
        if np.any(room < 0.0):
            worst = int(np.argmin(room))
            raise UnreachablePoseError(
                f"the seed's approximation has no pose at {what} {np.asarray(given).flat[worst]:g}"
                f" rad: |a cos + b sin| would have to be {abs(value.flat[worst]):.6g} m > "
                f"sqrt(a^2 + b^2) = {math.hypot(self.a, self.b):.6g} m"
            )
        return np.sqrt(room)

    def _solve_projection(
        self, value: np.ndarray, upper: float, given: np.ndarray, what: str
    ) -> np.ndarray:
        # a cos(x) + b sin(x) = value; the sign picks the side of (a, b):
        # -a sin(x) + b cos(x) = upper * s.
        s = self._root(value, given, what)
        norm = self.a**2 + self.b**2
        cos_x = (self.a * value + upper * self.b * s) / norm
        sin_x = (self.b * value - upper * self.a * s) / norm
        return np.arctan2(sin_x, cos_x)


def _circle_intersection(
    centre: np.ndarray,
    radius: float,
    other: np.ndarray,
    other_radius: float,
    sign: float,
    *,
    what: str,
    angles: np.ndarray,
) -> np.ndarray:
    """The point at *radius* from the fixed *centre* and *other_radius* from *other*.

    *sign* +1 takes the point counter-clockwise of the ray from *centre* to
    *other*, -1 the clockwise one.
    """
    ray = other - centre
    distance = np.hypot(ray[..., 0], ray[..., 1])
    too_far = distance > radius + other_radius
    too_near = distance < abs(radius - other_radius)
    if np.any(too_far | too_near | (distance == 0.0)):
        bad = too_far | too_near | (distance == 0.0)
        worst = int(np.argmax(bad))
        dist = float(distance.flat[worst])
        reach = f"[{abs(radius - other_radius):.6g}, {radius + other_radius:.6g}] m"
        raise UnreachablePoseError(
            f"the linkage cannot be assembled at {what} {float(angles.flat[worst]):g} rad: "
            f"the moving joint would need two links {dist:.6g} m apart to meet, "
            f"which they only do in {reach}"
        )
    along = (radius**2 - other_radius**2 + distance**2) / (2 * distance)
    across = np.sqrt(np.maximum(radius**2 - along**2, 0.0))
    unit = ray / distance[..., None]
    normal = np.stack([-unit[..., 1], unit[..., 0]], -1)  # counter-clockwise of the ray
    point: np.ndarray = centre + along[..., None] * unit + sign * across[..., None] * normal
    return point
