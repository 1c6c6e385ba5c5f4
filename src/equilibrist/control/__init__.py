"""Control and estimation: LQR, Kalman filters, LQG compensators, reference gains.

Layer ``control`` of equilibrist (it imports from ``numeric`` only). The
public API:

* :func:`lqr`, :func:`dlqr`, :func:`lqe`, :func:`dlqe` -- Riccati-based gains
  (python-control's conventions, without slycot);
* :func:`discretize`, :func:`van_loan`, :func:`discrete_noise` -- sampling a
  plant and its noise;
* :func:`reference_gain`, :func:`discrete_reference_gain` -- ``Kc``;
* :class:`DiscreteKalmanFilter` -- predict/update with the Joseph form, in
  the ``"current"`` and ``"predictor"`` forms;
* :func:`lqg_compensator` / :class:`Compensator` -- the seed's LQG
  compensator with inputs ``(u, y, r)``;
* :func:`controllability`, :func:`observability`, :func:`pole_table`,
  :func:`loop_margins` -- analysis;
* :func:`design` / :class:`Design` -- all of it for a system of the catalogue;
* :func:`to_statespace`, :func:`from_statespace` -- python-control interop;
  :func:`loop_at_input` -- a design's loop as implemented, broken at the
  plant input (the system of :attr:`Design.margins`).
"""

from equilibrist.control.analysis import (
    Margins,
    Mode,
    PoleInfo,
    Structure,
    controllability,
    loop_margins,
    observability,
    pole_table,
)
from equilibrist.control.design import design
from equilibrist.control.design_record import Design
from equilibrist.control.discretize import discrete_noise, discretize, van_loan
from equilibrist.control.interop import from_statespace, loop_at_input, to_statespace
from equilibrist.control.kalman import DiscreteKalmanFilter, Estimate, KalmanRun, SteadyStateGains
from equilibrist.control.lqg import Compensator, lqg_compensator
from equilibrist.control.reference import discrete_reference_gain, reference_gain
from equilibrist.control.riccati import LQESolution, LQRSolution, dlqe, dlqr, lqe, lqr

__all__ = [
    "Compensator",
    "Design",
    "DiscreteKalmanFilter",
    "Estimate",
    "KalmanRun",
    "LQESolution",
    "LQRSolution",
    "Margins",
    "Mode",
    "PoleInfo",
    "SteadyStateGains",
    "Structure",
    "controllability",
    "design",
    "discrete_noise",
    "discrete_reference_gain",
    "discretize",
    "dlqe",
    "dlqr",
    "from_statespace",
    "loop_at_input",
    "loop_margins",
    "lqe",
    "lqg_compensator",
    "lqr",
    "observability",
    "pole_table",
    "reference_gain",
    "to_statespace",
    "van_loan",
]
