"""Identification: the physical parameters of a derived model, fitted to a rig's log.

>>> from equilibrist import get_system
>>> from equilibrist.ident import identify, read_log
>>> cart = get_system("cartpole")
>>> result = identify(cart, read_log(cart, "run.csv"), ["m_p", "b_c", "b_p"])  # doctest: +SKIP
>>> result.params                  # every parameter, the free ones at their estimates  # doctest: +SKIP

The method: :mod:`equilibrist.ident.fit`; the log's format: :mod:`equilibrist.ident.log`.
"""

from equilibrist.ident.fit import identify
from equilibrist.ident.log import IdentificationError, Log, read_log
from equilibrist.ident.params import FORMAT, read_params, write_params
from equilibrist.ident.result import Estimate, Identification, OutputFit
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
