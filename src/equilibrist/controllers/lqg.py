"""``--controller lqg``: the LQR on the estimate of a discrete Kalman filter of the sensors."""

from __future__ import annotations

from equilibrist.controllers.kinds import ControllerKind, linear_builder
from equilibrist.controllers.lqr import DESIGN_DELAY

KIND = ControllerKind(
    name="lqg", label="LQG (Kalman filter + LQR)", help="Kalman filter on the measured outputs + LQR",
    build=linear_builder("lqg"), options=(DESIGN_DELAY,),
    noise="design", linear=True, loop="lqg", order=20,
)
