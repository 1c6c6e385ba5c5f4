"""equilibrist: underactuated balancing systems, from derivation to firmware.

The package is layered; each layer imports only from the ones before it::

    mechanics -> systems -> numeric -> control -> sim -> viz / export / cli

Nothing does work at import time: systems are derived (or loaded from the
on-disk cache) when first asked for. Inside IPython (Jupyter), importing the
package tells IPython how to show its objects (:mod:`equilibrist.notebook.display`,
by type name: nothing else is imported).
"""

from __future__ import annotations

import importlib
import sys
from typing import TYPE_CHECKING

from equilibrist.errors import EquilibristError

if TYPE_CHECKING:
    from equilibrist.controllers.loop_policy import Policy
    from equilibrist.numeric.system import System

__version__ = "0.1.0"

__all__ = ["EquilibristError", "__version__", "get_system", "list_systems", "policy"]


def get_system(name: str, **options: object) -> System:  # imports its module on first use
    """Return the :class:`~equilibrist.numeric.system.System` called *name*."""
    from equilibrist.numeric.lookup import get_system as _get

    return _get(name, **options)


def list_systems() -> list[str]:
    """Names of every system in the catalogue."""
    from equilibrist.systems.registry import family_names

    return family_names()


def _show_in_ipython() -> None:
    """Register the notebook display when IPython is running (its shell exists)."""
    if "IPython" not in sys.modules:
        return
    # By name: every layer imports this root module (for its errors and version), and none
    # may import the display, which sits with the applications above them.
    importlib.import_module("equilibrist.notebook.display").register()


_show_in_ipython()


def policy(system: System | str, *, controller: str = "lqr", rate: float | None = None,
           **options: object) -> Policy:  # imports its module on first use
    """Any controller kind for *system* as a :class:`~equilibrist.controllers.loop_policy.Policy`
    to step from a foreign loop (:func:`equilibrist.controllers.loop_policy.policy`)."""
    import importlib

    # By name: every layer imports this root module, and the kinds sit above most of them.
    module = importlib.import_module("equilibrist.controllers.loop_policy")
    made: Policy = module.policy(system, controller=controller, rate=rate, **options)
    return made
