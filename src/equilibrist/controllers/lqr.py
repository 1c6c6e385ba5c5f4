"""``--controller lqr``: the discrete LQR on the full state (every state measured)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.control.kinds import ControllerKind, ControllerRequest

if TYPE_CHECKING:
    from equilibrist.control.controller import LinearController


def build(request: ControllerRequest) -> LinearController:
    from equilibrist.control.controller import LinearController

    return LinearController.from_design(request.design(), kind="lqr", tracking=request.tracking)


KIND = ControllerKind(
    name="lqr", label="LQR (true state)", help="LQR on the full state (every state measured)", build=build,
    noise="design", linear=True, order=10,
)
