"""``--controller lqg``: the LQR on the estimate of a discrete Kalman filter of the sensors."""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.control.kinds import ControllerKind, ControllerRequest

if TYPE_CHECKING:
    from equilibrist.control.controller import LinearController


def build(request: ControllerRequest) -> LinearController:
    from equilibrist.control.controller import LinearController

    return LinearController.from_design(request.design(), kind="lqg", tracking=request.tracking)


KIND = ControllerKind(
    name="lqg", label="LQG (Kalman filter + LQR)", help="Kalman filter on the measured outputs + LQR", build=build,
    noise="design", linear=True, order=20,
)
