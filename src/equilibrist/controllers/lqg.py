"""``--controller lqg``: the LQR on the estimate of a discrete Kalman filter of the sensors."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from equilibrist.controllers.kinds import ControllerKind, ControllerRequest, Option
from equilibrist.controllers.lqr import DESIGN_DELAY

if TYPE_CHECKING:
    from equilibrist.control.linear import LinearController


def _cutoff(text: str) -> float:
    """A cutoff in Hz, finite and > 0."""
    value = float(text.strip().removesuffix("Hz").removesuffix("hz"))
    if not (math.isfinite(value) and value > 0):
        raise ValueError(text)
    return value


#: ``--design-velocity-filter``: the rig's low-pass of the measured rates that the Kalman
#: filter's model includes (:func:`equilibrist.control.design_extended.velocity_filtered`).
DESIGN_VELOCITY_FILTER = Option(
    "--design-velocity-filter",
    "the cutoff of the rig's low-pass of the measured rates (its --velocity-filter) that the "
    "Kalman filter's model includes, so it estimates the state from the filtered rates "
    "without their lag (measure the rates: --outputs; default none)",
    parse=_cutoff, metavar="HZ", expected="a cutoff in Hz > 0",
)


def _build(request: ControllerRequest) -> LinearController:
    """The request's design as the LQG, designed for the loop delay and the rig's velocity
    filter its options name (:func:`~equilibrist.control.design.kind_design`)."""
    from equilibrist.control.design import kind_design
    from equilibrist.control.linear import LinearController

    made = kind_design(request.design(), request.system, request.options)
    return LinearController.from_design(made, kind="lqg", tracking=request.tracking)


KIND = ControllerKind(
    name="lqg", label="LQG (Kalman filter + LQR)", help="Kalman filter on the measured outputs + LQR",
    build=_build, options=(DESIGN_DELAY, DESIGN_VELOCITY_FILTER),
    noise="design", linear=True, loop="lqg", order=20,
)
