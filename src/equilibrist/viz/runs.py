"""The read-only view of a run that the plots and animations draw.

A :class:`Run` holds, time-major, what one closed-loop run produced: true
and estimated states, inputs before and after saturation, measurements and
reference, with names and units, and the bound system (for its limits,
operating point and drawing). :func:`as_run` makes one from a simulation
result (``equilibrist.sim``); :meth:`Run.from_arrays` from plain arrays.
The viz layer never changes a result: it reads it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.viz.output import VizError

if TYPE_CHECKING:
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult


@dataclass(frozen=True, eq=False)
class Run:
    """One run, as the viz layer reads it: every array time-major, ``(n_steps, k)``.

    *u* is the input applied (after saturation), *u_command* the one asked for; *y* the
    measurements named by *output_names*; *reference* the tracked outputs' absolute
    reference, named by *reference_names*; *events* marked instants (a push); *fell* None
    when unknown; *x_op*, *u_op* the operating point the controller held (None: the plots
    ask the system for its canonical one). Arrays that are absent are None.
    """

    system: System
    t: np.ndarray
    x: np.ndarray
    u: np.ndarray | None = None
    u_command: np.ndarray | None = None
    estimate: np.ndarray | None = None
    y: np.ndarray | None = None
    output_names: tuple[str, ...] = ()
    reference: np.ndarray | None = None
    reference_names: tuple[str, ...] = ()
    label: str = ""
    events: tuple[tuple[float, str], ...] = field(default=())
    fell: bool | None = None
    x_op: np.ndarray | None = None
    u_op: np.ndarray | None = None

    @classmethod
    def from_arrays(
        cls,
        system: System,
        t: object,
        x: object,
        *,
        u: object | None = None,
        u_command: object | None = None,
        estimate: object | None = None,
        y: object | None = None,
        output_names: Sequence[str] = (),
        reference: object | None = None,
        reference_names: Sequence[str] = (),
        label: str = "",
        events: Iterable[tuple[float, str]] = (),
        fell: bool | None = None,
        x_op: object | None = None,
        u_op: object | None = None,
    ) -> Run:
        """A run from time-major arrays, checked against the system's sizes (:class:`VizError`)."""
        tt = np.asarray(t, float).reshape(-1)
        n, ns, ni = len(tt), len(system.state_names), len(system.input_names)
        problems: list[str] = []
        if n == 0:
            problems.append("no sample times")
        if n > 1 and not np.all(np.diff(tt) > 0):
            problems.append("sample times must increase")

        def arr(name: str, value: object | None, cols: int | None) -> np.ndarray | None:
            if value is None:
                return None
            a = np.asarray(value, float)
            if a.ndim == 1 and cols == 1:
                a = a[:, None]
            if a.ndim != 2 or a.shape[0] != n or (cols is not None and a.shape[1] != cols):
                want = f"({n}, {cols if cols is not None else 'k'})"
                problems.append(f"{name} has shape {a.shape}, expected {want} (time-major)")
                return None
            return a

        xs = arr("x", x, ns)
        us = arr("u", u, ni)
        uc = arr("u_command", u_command, ni)
        est = arr("estimate", estimate, ns)
        ys = arr("y", y, len(output_names) or None)
        ref = arr("reference", reference, len(reference_names) or None)
        if ys is not None and ys.shape[1] != len(output_names):
            problems.append(f"y has {ys.shape[1]} columns but {len(output_names)} output names")
        if ref is not None and ref.shape[1] != len(reference_names):
            problems.append(f"reference has {ref.shape[1]} columns but {len(reference_names)} names")
        for name in (*output_names, *reference_names):
            if name not in system.state_names:
                problems.append(f"{name!r} is not a state of {system.key}")
        xo = None if x_op is None else np.asarray(x_op, float).reshape(-1)
        uo = None if u_op is None else np.asarray(u_op, float).reshape(-1)
        if xo is not None and xo.size != ns:
            problems.append(f"x_op has {xo.size} values, expected {ns}")
        if uo is not None and uo.size != ni:
            problems.append(f"u_op has {uo.size} values, expected {ni}")
        if problems:
            raise VizError(f"cannot show this run of {system.key}: " + "; ".join(problems))
        return cls(system=system, t=tt, x=xs, u=us, u_command=uc, estimate=est, y=ys,  # type: ignore[arg-type]
                   output_names=tuple(output_names), reference=ref,
                   reference_names=tuple(reference_names), label=label,
                   events=tuple((float(a), str(b)) for a, b in events), fell=fell,
                   x_op=xo, u_op=uo)

    # -- names ---------------------------------------------------------------------
    @property
    def key(self) -> str:
        return str(self.system.key)

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(self.system.state_names)

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(self.system.input_names)

    @property
    def state_units(self) -> tuple[str, ...]:
        return tuple(self.system.state_units)

    @property
    def input_units(self) -> tuple[str, ...]:
        return tuple(self.system.input_units)

    def state(self, name: str) -> np.ndarray:
        """The true state *name* over time."""
        return self.x[:, self._index(name)]

    def _index(self, name: str) -> int:
        if name not in self.state_names:
            from equilibrist.errors import UnknownNameError, nearest

            raise UnknownNameError(f"{self.key} has no state {name!r}: {nearest(name, self.state_names)}")
        return self.state_names.index(name)

    def with_label(self, label: str) -> Run:
        from dataclasses import replace

        return replace(self, label=label)


def as_run(result: SimResult | Run, *, system: System | None = None, label: str | None = None) -> Run:
    """The :class:`Run` view of a simulation result (or a Run itself); *system* defaults to
    the one rebuilt from the result's name and parameters, *label* to the result's own."""
    if isinstance(result, Run):
        return result if label is None else result.with_label(label)
    from equilibrist.viz import adapt as _adapt

    return _adapt.run_from_result(result, system=system, label=label)
