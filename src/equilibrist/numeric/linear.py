"""Linear models: the linearization of a system about an operating point."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from equilibrist.errors import DimensionError, UnknownNameError, nearest


@dataclass(frozen=True, eq=False)
class LinearModel:
    """``dx_dot = A dx + B du``, ``dy = C dx + D du`` in deviation coordinates.

    ``dx = x - x0`` and ``du = u - u0`` (seed 000's shift: an initial
    condition ``x(0)`` becomes ``x(0) - x0``). ``dt`` is None for continuous
    time, the sample period for a discrete model.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    x0: np.ndarray
    u0: np.ndarray
    residual: float = 0.0
    system: str = ""
    params: Mapping[str, float] = field(default_factory=dict)
    dt: float | None = None
    state_units: tuple[str, ...] = ()
    input_units: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n, m, p = len(self.state_names), len(self.input_names), len(self.output_names)
        for label, mat, shape in (
            ("A", self.A, (n, n)),
            ("B", self.B, (n, m)),
            ("C", self.C, (p, n)),
            ("D", self.D, (p, m)),
        ):
            if np.shape(mat) != shape:
                raise DimensionError(f"{label} has shape {np.shape(mat)}, expected {shape}")

    def __repr__(self) -> str:  # one line; a notebook shows the matrices (equilibrist.notebook)
        timebase = "continuous" if self.dt is None else f"dt={self.dt:g} s"
        return (f"LinearModel({self.system or '?'}, {timebase}, states={list(self.state_names)}, "
                f"inputs={list(self.input_names)}, outputs={list(self.output_names)})")

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_outputs(self) -> int:
        return len(self.output_names)

    @property
    def is_discrete(self) -> bool:
        return self.dt is not None

    @property
    def y0(self) -> np.ndarray:
        """Outputs at the operating point."""
        y0: np.ndarray = self.C @ self.x0 + self.D @ self.u0
        return y0

    def deviation(self, x: np.ndarray) -> np.ndarray:
        """``x - x0``: absolute state to deviation coordinates."""
        dx: np.ndarray = np.asarray(x, dtype=float) - self.x0
        return dx

    def absolute(self, dx: np.ndarray) -> np.ndarray:
        """``x0 + dx``: deviation back to absolute coordinates."""
        x: np.ndarray = np.asarray(dx, dtype=float) + self.x0
        return x

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A``, sorted by real part (magnitude when discrete)."""
        ev = np.linalg.eigvals(self.A)
        key = np.abs(ev) if self.is_discrete else ev.real
        return ev[np.argsort(key, kind="stable")]

    def output_index(self, names: tuple[str, ...] | list[str]) -> list[int]:
        out = []
        for n in names:
            if n not in self.state_names:
                raise UnknownNameError(
                    f"unknown output {n!r}: {nearest(n, self.state_names)}"
                )
            out.append(self.state_names.index(n))
        return out

    def with_outputs(self, names: tuple[str, ...] | list[str]) -> LinearModel:
        """The same model measuring the states *names* instead."""
        idx = self.output_index(names)
        C = np.zeros((len(idx), self.n_states))
        C[np.arange(len(idx)), idx] = 1.0
        return LinearModel(
            A=self.A,
            B=self.B,
            C=C,
            D=np.zeros((len(idx), self.n_inputs)),
            state_names=self.state_names,
            input_names=self.input_names,
            output_names=tuple(names),
            x0=self.x0,
            u0=self.u0,
            residual=self.residual,
            system=self.system,
            params=self.params,
            dt=self.dt,
            state_units=self.state_units,
            input_units=self.input_units,
        )
