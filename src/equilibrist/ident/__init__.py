"""Identification: the physical parameters of a derived model, fitted to a rig's log.

>>> from equilibrist import get_system
>>> from equilibrist.ident import identify, read_log
>>> cart = get_system("cartpole")
>>> result = identify(cart, read_log(cart, "run.csv"), ["m_p", "b_c", "b_p"])  # doctest: +SKIP
>>> result.params                  # every parameter, the free ones at their estimates  # doctest: +SKIP

See :mod:`equilibrist.ident.fit` for the method (multiple shooting for the start, then the
prediction errors of the model's Kalman filter) and
:mod:`equilibrist.ident.log` for the log's format.
"""

from equilibrist.ident.fit import identify
from equilibrist.ident.log import IdentificationError, Log, read_log
from equilibrist.ident.params import read_params, write_params
from equilibrist.ident.result import FORMAT, Estimate, Identification, OutputFit
from equilibrist.ident.shooting import BACKENDS

__all__ = [
    "BACKENDS",
    "FORMAT",
    "Estimate",
    "Identification",
    "IdentificationError",
    "Log",
    "OutputFit",
    "identify",
    "read_log",
    "read_params",
    "write_params",
]
