"""``--controller lqr``: the discrete LQR on the full state (every state measured)."""

from __future__ import annotations

from equilibrist.controllers.kinds import ControllerKind, linear_builder

KIND = ControllerKind(
    name="lqr", label="LQR (true state)", help="LQR on the full state (every state measured)",
    build=linear_builder("lqr"),
    noise="design", linear=True, loop="lqr", order=10,
)
