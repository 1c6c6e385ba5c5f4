"""The linear controller's library in C for the exports: translated from its one definition.

:func:`linear_c` is :data:`~equilibrist.native.linear_layout.LINEAR_SOURCE` (the
library the simulation core compiles and
:class:`~equilibrist.control.linear.LinearController` runs as Python) translated to C by :mod:`equilibrist.native.pyc`, with the sizes of
one controller as literals (the core's own form for a controller of those
sizes): ``eq_linear_output``, ``eq_linear_update`` and ``eq_linear_estimate``
over the controller's packed vector (:func:`deviation_vector`), the same sums
in the same order. So in double precision, built without fused
multiply-adds, the exported controller and the simulated one agree to the
last bit, and nothing of the library is written a second time by hand. In
single precision the translation's ``double`` is the export's real type.

It is tested on its own (``tests/export/test_export_linear_c.py``) against the
Python controller on random forms, in double and single precision.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.native.controller_c import translate_controller
from equilibrist.native.linear_layout import (
    LINEAR_HEADER,
    LINEAR_SOURCE,
    linear_layout_source,
)

if TYPE_CHECKING:
    from equilibrist.control.linear import LinearController

# The functions in C, every array a pointer followed by its length (int64_t):
#   eq_linear_output(t, z, nz, y, ny, r, nr, p, np, u_out, m)
#   eq_linear_update(t, z, nz, y, ny, r, nr, u_applied, m, p, np, z_out, nz)
#   eq_linear_estimate(t, z, nz, y, ny, r, nr, p, np, x_out, n)


def linear_c(sizes: Mapping[str, int], real: str = "double") -> str:
    """The library in C for controllers of *sizes* (``nz, ny, nr, m, n``), in *real*
    (``"double"`` or ``"float"``): static functions ``eq_linear_*`` (needs ``<stdint.h>``)."""
    fixed = {key: int(sizes[key]) for key in ("nz", "ny", "nr", "m", "n")}
    mod, _ = translate_controller(
        linear_layout_source(fixed) + LINEAR_SOURCE,
        {role: f"linear_{role}" for role in ("output", "update", "estimate")},
        prefix="eq_", library="")
    text: str = mod.c_source()
    if real != "double":
        text = re.sub(r"\bdouble\b", real, text)
    return ("/* ---- The linear controller's library, translated from its Python definition "
            "(equilibrist.control.controller.LINEAR_SOURCE). ---- */\n" + text
            + "/* ---- end of the linear controller's library ---- */\n")


def deviation_vector(lin: LinearController) -> np.ndarray:
    """*lin*'s packed vector (:attr:`LinearController.packed`) with its ``x_op`` block zero:
    ``eq_linear_estimate`` then writes the estimate's deviation from the operating point,
    ``Ez z + Ey (y - y_op)``, the sum :attr:`LinearController.estimate` adds to ``x_op``."""
    p = lin.packed()
    start = int(p[LINEAR_HEADER.index("x_op")])
    p[start:start + int(p[LINEAR_HEADER.index("n")])] = 0.0
    return p


__all__ = ["deviation_vector", "linear_c"]
