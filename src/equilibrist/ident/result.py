"""The answer of :func:`equilibrist.ident.fit.identify`: the estimates, the fit of each
measured output, and their reports (for people, as JSON, as a parameters file)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from equilibrist.errors import nearest
from equilibrist.ident.log import IdentificationError
from equilibrist.ident.params import FORMAT

# Lags of the Ljung-Box whiteness test, and its level.
WHITENESS_LAGS = 20
WHITENESS_LEVEL = 0.05


@dataclass(frozen=True)
class Estimate:
    """One fitted quantity: value, standard error, start value and unit."""

    name: str
    value: float
    std_error: float
    start: float
    unit: str

    @property
    def relative_error(self) -> float:
        """Standard error over estimate (infinite for an estimate at zero)."""
        if abs(self.value) <= 1e-9 * max(abs(self.std_error), abs(self.start), 1e-300):
            return math.inf
        return abs(self.std_error / self.value)


@dataclass(frozen=True)
class OutputFit:
    """Fit quality of one measured output."""

    name: str
    unit: str
    nrmse: float
    rms_residual: float
    sensor_std: float
    ljung_box_q: float
    ljung_box_p: float
    lags: int

    @property
    def fit_percent(self) -> float:
        return 100.0 * (1.0 - self.nrmse)

    @property
    def white(self) -> bool:
        return self.ljung_box_p >= WHITENESS_LEVEL


@dataclass(frozen=True, eq=False)
class Identification:
    """The answer of :func:`~equilibrist.ident.fit.identify`.

    *params* holds every parameter, the free ones at their estimates; *estimates* the free
    parameters, then the sensor offsets (``offset_<output>``), with *correlation* in their
    order; *unidentifiable* the directions the log cannot tell apart, in words; *replayed*
    the fitted model's replay, each shooting segment (starting at *segment_starts*) from its
    estimated state; *method* how the fit was made (JSON-able).
    """

    system: str
    params: Mapping[str, float]
    free: tuple[str, ...]
    estimates: tuple[Estimate, ...]
    correlation: np.ndarray
    unidentifiable: tuple[str, ...]
    warnings: tuple[str, ...]
    outputs: tuple[OutputFit, ...]
    output_names: tuple[str, ...]
    time: np.ndarray
    measured: np.ndarray
    replayed: np.ndarray
    segment_starts: np.ndarray
    initial_state: Mapping[str, float]
    method: Mapping[str, object]
    source: str = ""
    noise: Mapping[str, object] = field(default_factory=dict)

    def estimate(self, name: str) -> Estimate:
        for e in self.estimates:
            if e.name == name:
                return e
        raise IdentificationError(f"no estimate {name!r}: {nearest(name, [e.name for e in self.estimates])}")

    def to_dict(self) -> dict[str, object]:
        """Everything as JSON-able data (``--json``)."""
        names = [e.name for e in self.estimates]
        return {
            "system": self.system,
            "log": self.source,
            "method": dict(self.method),
            "estimates": {
                e.name: {"value": e.value, "std_error": _finite_or_none(e.std_error),
                         "relative_error": _finite_or_none(e.relative_error),
                         "start": e.start, "unit": e.unit}
                for e in self.estimates
            },
            "correlation": {"names": names, "matrix": self.correlation.tolist()},
            "unidentifiable": list(self.unidentifiable),
            "warnings": list(self.warnings),
            "outputs": {
                o.name: {"nrmse": o.nrmse, "fit_percent": o.fit_percent,
                         "rms_residual": o.rms_residual, "sensor_std": o.sensor_std,
                         "unit": o.unit,
                         "whiteness": {"test": "Ljung-Box", "lags": o.lags, "q": o.ljung_box_q,
                                       "p_value": o.ljung_box_p, "white": o.white,
                                       "level": WHITENESS_LEVEL}}
                for o in self.outputs
            },
            "initial_state": dict(self.initial_state),
            "noise": dict(self.noise),
            "params": dict(self.params),
        }

    def params_document(self) -> dict[str, object]:
        """What ``--out params.json`` holds (read back by ``--params``)."""
        return {
            "format": FORMAT,
            "system": self.system,
            "params": dict(self.params),
            "identified": {e.name: {"value": e.value, "std_error": _finite_or_none(e.std_error)}
                           for e in self.estimates if e.name in self.free},
            "log": self.source,
            "method": self.method.get("name"),
        }

    def summary(self) -> str:
        """A report for people."""
        m = self.method
        lines = [
            f"{self.system}: {len(self.free)} parameter{'s' if len(self.free) != 1 else ''} "
            f"identified from {self.source or 'the log'} ({m['samples']} samples, "
            f"{m['duration']:g} s; outputs {', '.join(self.output_names)})",
            f"method: {m['description']}",
            "",
        ]
        rows = []
        for e in self.estimates:
            rel = "-" if not math.isfinite(e.relative_error) else f"{100 * e.relative_error:.2g} %"
            se = "not determined" if not math.isfinite(e.std_error) else f"{e.std_error:.4g}"
            rows.append((e.name, f"{e.value:.6g}", se, rel, f"{e.start:.6g}", e.unit))
        lines.append(_table(("estimate", "value", "std error", "relative", "start", "unit"), rows))
        if len(self.estimates) > 1:
            lines += ["", "correlation:"]
            names = [e.name for e in self.estimates]
            width = max(len(n) for n in names)
            col = max(10, width + 2)
            lines.append(" " * (width + 2) + "".join(f"{n:>{col}}" for n in names))
            for n, row in zip(names, self.correlation, strict=True):
                lines.append(f"  {n:<{width}}" + "".join(
                    f"{v:>{col}.3f}" if math.isfinite(v) else f"{'-':>{col}}" for v in row))
        lines += ["", "fit per output (replayed segment by segment):"]
        rows = [(o.name, f"{o.nrmse:.4f}", f"{o.fit_percent:.1f} %", f"{o.rms_residual:.3g} {o.unit}",
                 f"{o.sensor_std:.3g} {o.unit}",
                 f"Q({o.lags}) = {o.ljung_box_q:.1f}, p = {o.ljung_box_p:.3f}: "
                 f"{'white' if o.white else 'NOT white'}")
                for o in self.outputs]
        lines.append(_table(("output", "NRMSE", "fit", "residual rms", "sensor std",
                             "whiteness (Ljung-Box)"), rows))
        if self.unidentifiable:
            lines += ["", "not identifiable from this log:"]
            lines += [f"  - {w}" for w in self.unidentifiable]
        if self.warnings:
            lines += ["", "warnings:"]
            lines += [f"  - {w}" for w in self.warnings]
        return "\n".join(lines)


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    cells = [list(header)] + [list(r) for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    out = []
    for k, r in enumerate(cells):
        out.append("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
        if k == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out)


__all__ = ["WHITENESS_LAGS", "WHITENESS_LEVEL", "Estimate", "Identification", "OutputFit"]
