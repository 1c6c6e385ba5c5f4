"""Jupyter: every object shown inline, and sliders over a design.

* :mod:`equilibrist.notebook.display` -- how systems, linear models, designs,
  compensators, results, batches and figures show (registered with IPython when
  ``equilibrist`` is imported inside it; :func:`register` does it by hand);
* :func:`explore` -- the design's weights and the system's parameters as sliders
  that redesign and simulate again (``pip install 'equilibrist[notebook]'``).

This package sits above the libraries it shows (``viz``, ``sim``, ``control``);
nothing below imports it.
"""

from typing import TYPE_CHECKING

from equilibrist._lazy import exports

if TYPE_CHECKING:
    from equilibrist.notebook.display import register
    from equilibrist.notebook.widgets import Explorer, explore

__all__ = ["Explorer", "explore", "register"]

__getattr__ = exports(
    __name__,
    {
        "register": "equilibrist.notebook.display",
        "Explorer": "equilibrist.notebook.widgets",
        "explore": "equilibrist.notebook.widgets",
    },
    globals(),
)
