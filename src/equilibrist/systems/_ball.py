"""A solid ball rolling without slipping on a rotating beam (shared by two systems).

The ball and beam and its servo-driven reduction derive from the same
geometry; it lives here once. (The derivation cache hashes the systems'
helper modules, so a change here re-derives both.)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class RollingBall:
    """The beam frame, the ball body and the points the friction acts at."""

    beam_frame: Any
    ball: Any
    centre: Any
    beam_point: Any


def rolling_ball(N: Any, O: Any, theta: Any, thetad: Any, R: Any, *, m: Any, r: Any,
                 offset: Any, name: str) -> RollingBall:
    """A ball of mass *m*, radius *r* at distance *R* along a beam turned by *theta*.

    The ball's centre sits *offset* above the line through the pivot along
    the beam. Its spin is not typed in: it comes from the rolling condition
    (the ball's and the beam's material points at the contact move
    together), which gives ``theta_dot - R_dot / r``.
    """
    import sympy as sp
    from sympy.physics import mechanics as me

    B = N.orientnew("B", "Axis", (theta, N.z))
    B.set_ang_vel(N, thetad * N.z)
    centre = O.locatenew("C", R * B.x + offset * B.y)
    centre.set_vel(N, centre.pos_from(O).dt(N))
    # The beam's material point under the ball's centre: the reaction of the
    # rolling friction acts there, so only the relative motion R_dot dissipates.
    beam_point = O.locatenew("Cb", R * B.x + offset * B.y)
    beam_point.v2pt_theory(O, N, B)
    spin = sp.Symbol("spin")
    S = N.orientnew("S", "Axis", (sp.Symbol("ball_angle"), N.z))
    S.set_ang_vel(N, spin * N.z)
    contact_ball = centre.locatenew("K", -r * B.y)
    contact_ball.v2pt_theory(centre, N, S)
    contact_beam = O.locatenew("Kb", R * B.x + (offset - r) * B.y)
    contact_beam.v2pt_theory(O, N, B)
    slip = (contact_ball.vel(N) - contact_beam.vel(N)).express(B)
    (spin_rate,) = sp.solve(slip.dot(B.x), spin)
    if slip.dot(B.y).subs(spin, spin_rate) != 0:
        raise RuntimeError(f"{name}: the rolling condition has a normal component")
    S.set_ang_vel(N, spin_rate * N.z)
    ball = me.RigidBody(
        "ball", centre, S, m, (me.inertia(S, 0, 0, sp.Rational(2, 5) * m * r**2), centre)
    )
    return RollingBall(B, ball, centre, beam_point)
