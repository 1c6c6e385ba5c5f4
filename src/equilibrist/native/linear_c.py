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

:class:`ControllerData` is what a linear controller's exported library is written from
(:mod:`equilibrist.native.linear_library`, :mod:`equilibrist.native.c_programs`): names,
arrays and the packed form, made by the export from the controller the simulation runs.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from equilibrist.native.c_text import c_identifier
from equilibrist.native.controller_c import translate_controller
from equilibrist.native.linear_layout import (
    LINEAR_BLOCKS,
    LINEAR_HEADER,
    LINEAR_SOURCE,
    linear_layout_source,
)

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


def deviation_vector(packed: np.ndarray) -> np.ndarray:
    """A linear controller's *packed* vector with its ``x_op`` block zero:
    ``eq_linear_estimate`` then writes the estimate's deviation from the operating point,
    ``Ez z + Ey (y - y_op)``, the sum the controller's estimate adds to ``x_op``."""
    p = np.array(packed, dtype=float)
    start = int(p[LINEAR_HEADER.index("x_op")])
    p[start:start + int(p[LINEAR_HEADER.index("n")])] = 0.0
    p.setflags(write=False)
    return p


@dataclass(frozen=True, eq=False)
class ControllerData:
    """A digital linear controller ready to be written as C.

    ``packed`` is the controller's packed form (:mod:`equilibrist.native.linear_layout`,
    its estimate in deviations: :func:`deviation_vector`), what the C step runs; the
    design's plant and gains (``Ad``, ``Bd``, ``K``, ``Kf``, ``Kc``) are the header's
    record. ``z0`` is the controller's state at the start and ``state_map`` the map from
    a state's deviation to it (``init_at``). ``form`` is the Kalman form (``"current"``,
    ``"predictor"``; ``""`` without a filter), ``controller`` the form's name (``"lqg"``,
    ``"lqr"``); ``params``, ``weights`` and ``settings`` are the design's, for the record.
    """

    system: str
    controller: str
    form: str
    dt: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    measured_names: tuple[str, ...]
    tracked_names: tuple[str, ...]
    state_units: tuple[str, ...]
    input_units: tuple[str, ...]
    x0: np.ndarray
    u0: np.ndarray
    r0: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    K: np.ndarray
    Kf: np.ndarray
    Kc: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    packed: np.ndarray
    z0: np.ndarray
    state_map: np.ndarray
    params: Mapping[str, float] = field(default_factory=dict)
    weights: Mapping[str, np.ndarray] = field(default_factory=dict)
    settings: Mapping[str, str] = field(default_factory=dict)

    @property
    def filtered(self) -> bool:
        """Whether a Kalman filter estimates the state from the measurements."""
        return bool(self.form)

    @property
    def measured_units(self) -> tuple[str, ...]:
        return tuple(self.state_units[i] for i in self.measured_index)

    @property
    def y0(self) -> np.ndarray:
        """Measurements at the operating point."""
        return _readonly(self.C @ self.x0)

    @property
    def C(self) -> np.ndarray:
        """The measurement matrix: a selection of the states."""
        return _readonly(np.eye(self.n_states)[list(self.measured_index)].reshape(
            self.n_measured, self.n_states))

    @property
    def sizes(self) -> dict[str, int]:
        """The linear form's sizes (``nz``, ``ny``, ``nr``, ``m``, ``n``), from its header."""
        return {key: int(self.packed[LINEAR_HEADER.index(key)])
                for key in ("nz", "ny", "nr", "m", "n")}

    @property
    def form_shapes(self) -> list[tuple[str, int, int]]:
        """``(name, rows, columns)`` of each matrix of the linear form."""
        sizes = self.sizes
        return [(label, sizes[dims[0]], sizes[dims[1]])
                for label, dims in LINEAR_BLOCKS if len(dims) == 2]

    @property
    def n_z(self) -> int:
        """States of the controller (the Kalman prediction; 0 for LQR)."""
        return self.sizes["nz"]

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_measured(self) -> int:
        return len(self.measured_names)

    @property
    def n_references(self) -> int:
        return len(self.tracked_names)

    @property
    def rate(self) -> float:
        """Sample rate [Hz]."""
        return 1.0 / self.dt

    @property
    def measured_index(self) -> tuple[int, ...]:
        """Index of the state each measurement reads."""
        return tuple(self.state_names.index(o) for o in self.measured_names)

    @property
    def name(self) -> str:
        """The library's name and C prefix (``cartpole_lqg``)."""
        return f"{c_identifier(self.system)}_{self.controller}"

    @property
    def fingerprint(self) -> str:
        """12 hex digits identifying the controller's numbers and names."""
        h = hashlib.sha256()
        for label in ("controller", "form", "system"):
            h.update(str(getattr(self, label)).encode())
        for names in (self.state_names, self.input_names, self.measured_names, self.tracked_names):
            h.update(",".join(names).encode() + b";")
        h.update(np.float64(self.dt).tobytes())
        for arr in (self.x0, self.u0, self.y0, self.r0, self.Ad, self.Bd, self.C, self.K,
                    self.Kf, self.Kc, self.u_min, self.u_max):
            h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
        return h.hexdigest()[:12]


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


__all__ = ["ControllerData", "deviation_vector", "linear_c"]
