"""The result of a simulated run: named, time-major arrays, the settings, the metrics.

Rows are the controller's samples ``t_k = k T``: row ``k`` holds the true
state at ``t_k``, the measurement taken then, the controller's estimate and
command, and the input applied from ``t_k`` to ``t_k+1``. A run that fell
stops at the last sample before the fall; ``fell_at`` is the time (on the
physics grid) at which a state left the system's region.

A result saves to ``.npz`` (lossless: the arrays bit for bit, the settings as
JSON) and exports to CSV (one column per named quantity, unit in the header,
17 significant digits, so the CSV is lossless too).
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from equilibrist.errors import SimulationError, UnknownNameError, nearest

FORMAT = "equilibrist-simresult-1"

_ARRAYS = ("time", "states", "estimates", "measurements", "commanded", "saturated", "applied",
           "reference")


def _names(label: str, names: tuple[str, ...], name: str) -> int:
    if name not in names:
        if not names:
            raise UnknownNameError(f"the run has no {label}s (asked for {name!r})")
        raise UnknownNameError(f"no {label} {name!r}: {nearest(name, names)}")
    return names.index(name)


@dataclass(frozen=True, eq=False)
class SimResult:
    """One simulated run.

    Attributes
    ----------
    system : str
        The system's key.
    params : mapping
        The plant's parameter values at the start of the run.
    time : ndarray, shape (n_rows,)
        Sample times [s].
    states, estimates : ndarray, shape (n_rows, n_states)
        True state and the controller's estimate (absolute). ``estimates`` is
        None for a controller without one.
    measurements : ndarray, shape (n_rows, n_outputs)
        What the sensors read (absolute, with noise).
    commanded, saturated, applied : ndarray, shape (n_rows, n_inputs)
        The controller's command; the command after the actuator's limits;
        the input that acted on the plant over the following sample
        (the saturated command, one sample late when the run delays).
    reference : ndarray, shape (n_rows, n_tracked)
        The reference of the tracked outputs (zero columns without one).
    fell, fell_at, fell_state, fell_x :
        Whether and when the run fell, which state left its region
        (``"not finite"`` when the state diverged), and the state then.
    settings : mapping
        Everything that produced the run (JSON-able), including the seed.
    """

    system: str
    params: Mapping[str, float]
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    input_names: tuple[str, ...]
    input_units: tuple[str, ...]
    output_names: tuple[str, ...]
    reference_names: tuple[str, ...]
    time: np.ndarray
    states: np.ndarray
    estimates: np.ndarray | None
    measurements: np.ndarray
    commanded: np.ndarray
    saturated: np.ndarray
    applied: np.ndarray
    reference: np.ndarray
    x_op: np.ndarray
    u_op: np.ndarray
    fell: bool
    fell_at: float | None
    fell_state: str | None
    fell_x: np.ndarray | None
    final_state: np.ndarray
    settings: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in (*_ARRAYS, "x_op", "u_op", "fell_x", "final_state"):
            value = getattr(self, name)
            if value is not None:
                arr = np.asarray(value)
                if arr.flags.writeable:
                    arr = arr.copy()
                    arr.setflags(write=False)
                object.__setattr__(self, name, arr)
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))

    def __repr__(self) -> str:
        end = f"fell at {self.fell_at:g} s ({self.fell_state})" if self.fell else "stayed up"
        ctrl = self.settings.get("controller", {})
        kind = ctrl.get("kind", "?") if isinstance(ctrl, Mapping) else "?"
        return (f"SimResult({self.system}, {kind}, {self.n_rows} samples at "
                f"{self.settings.get('rate', float('nan')):g} Hz, {end})")

    # -- names --------------------------------------------------------------
    @property
    def n_rows(self) -> int:
        return int(self.time.shape[0])

    @property
    def dt(self) -> float:
        """The control period [s]."""
        return 1.0 / float(self.settings["rate"])

    @property
    def output_units(self) -> tuple[str, ...]:
        return tuple(self.state_units[self.state_names.index(o)] for o in self.output_names)

    def unit(self, name: str) -> str:
        """The unit of a state, input or output called *name*."""
        if name in self.state_names:
            return self.state_units[self.state_names.index(name)]
        if name in self.input_names:
            return self.input_units[self.input_names.index(name)]
        raise UnknownNameError(
            f"no state or input {name!r}: {nearest(name, self.state_names + self.input_names)}"
        )

    def state(self, name: str) -> np.ndarray:
        """The true state *name* over time."""
        return self.states[:, _names("state", self.state_names, name)]

    def estimate(self, name: str) -> np.ndarray:
        """The controller's estimate of state *name* over time."""
        if self.estimates is None:
            raise SimulationError("this run's controller makes no state estimate")
        return self.estimates[:, _names("state", self.state_names, name)]

    def input(self, name: str) -> np.ndarray:
        """The input *name* that acted on the plant (saturated, delayed when asked)."""
        return self.applied[:, _names("input", self.input_names, name)]

    def command(self, name: str) -> np.ndarray:
        """The controller's command for input *name*, before saturation."""
        return self.commanded[:, _names("input", self.input_names, name)]

    def measurement(self, name: str) -> np.ndarray:
        """The sensor reading of output *name*."""
        return self.measurements[:, _names("output", self.output_names, name)]

    def reference_of(self, name: str) -> np.ndarray:
        """The reference of the tracked output *name*."""
        return self.reference[:, _names("tracked output", self.reference_names, name)]

    @property
    def stayed_up(self) -> bool:
        return not self.fell

    # -- metrics ------------------------------------------------------------
    def metrics(self, *, settle_fraction: float = 0.02) -> dict[str, Any]:
        """Summary metrics of the run.

        ``settling_time``: the time after which every watched output stays
        within ``settle_fraction`` of its largest deviation from its target,
        or within its noise floor where that is wider (the offset plus four
        standard deviations of the output over the last fifth of the run);
        None if it never settles or the run fell. Watched outputs are the
        tracked outputs when tracking (target: the final reference), else the
        measured outputs (target: the operating point).
        ``overshoot``: per watched output, the largest excursion past the
        target on the side opposite the initial error, as a fraction of that
        error (None for an output that starts on target).
        ``peak_input``: the largest ``|command|``; ``rms_input``: RMS of the
        applied input (both absolute, per input); ``time_saturated``: time
        with any command outside its limits [s]; ``final_error``: watched
        output minus target at the end; ``estimation_error_rms``: RMS of
        estimate minus truth per state (None without estimate).
        """
        if not 0 < settle_fraction < 1:
            raise SimulationError(f"settle_fraction must be in (0, 1), got {settle_fraction}")
        dt = self.dt
        watched, errors = self._watched_errors()
        overshoot: dict[str, float | None] = {}
        settle_idx = 0
        settled = True
        for j, name in enumerate(watched):
            e = errors[:, j]
            e0 = e[0]
            if abs(e0) > 0:
                past = -np.sign(e0) * e
                overshoot[name] = float(max(0.0, past.max()) / abs(e0))
            else:
                overshoot[name] = None
            scale = float(np.abs(e).max())
            if scale == 0:
                continue
            # A noisy loop never enters a band thinner than its own noise: the
            # band is also at least the steady spread of the last fifth of the
            # run (its offset plus four standard deviations).
            tail = e[int(0.8 * len(e)) :]
            floor = float(abs(tail.mean()) + 4.0 * tail.std()) if tail.size > 1 else 0.0
            band = max(settle_fraction * scale, floor)
            outside = np.nonzero(np.abs(e) > band)[0]
            if outside.size:
                last = int(outside[-1])
                if last == len(e) - 1:
                    settled = False
                settle_idx = max(settle_idx, last + 1)
        settling = None if (self.fell or not settled) else float(self.time[min(settle_idx, self.n_rows - 1)])
        sat_rows = np.any(self.saturated != self.commanded, axis=1) if self.commanded.size else np.zeros(self.n_rows, bool)
        est_rms = None
        if self.estimates is not None:
            err = self.estimates - self.states
            est_rms = dict(zip(self.state_names, np.sqrt(np.mean(err**2, axis=0)).tolist(), strict=True))
        return {
            "system": self.system,
            "fell": bool(self.fell),
            "fell_at": None if self.fell_at is None else round(float(self.fell_at), 12),
            "fell_state": self.fell_state,
            "stayed_up": not self.fell,
            "duration": float(self.time[-1]) if self.n_rows else 0.0,
            "settling_time": settling,
            "overshoot": overshoot,
            "peak_input": dict(zip(self.input_names, np.abs(self.commanded).max(axis=0).tolist(), strict=True)),
            "rms_input": dict(zip(self.input_names, np.sqrt(np.mean(self.applied**2, axis=0)).tolist(), strict=True)),
            # Samples whose command was clipped, times the sample period (the
            # compiled batch counts the same way, the last sample included).
            "time_saturated": float(np.count_nonzero(sat_rows) * dt),
            "final_error": dict(zip(watched, errors[-1].tolist(), strict=True)),
            "estimation_error_rms": est_rms,
            "peak_deviation": dict(zip(self.state_names, np.abs(self.states - self.x_op).max(axis=0).tolist(), strict=True)),
            "seed": self.settings.get("seed"),
        }

    def _watched_errors(self) -> tuple[tuple[str, ...], np.ndarray]:
        if self.reference_names:
            idx = [self.state_names.index(r) for r in self.reference_names]
            target = self.reference[-1]
            return self.reference_names, self.states[:, idx] - target
        names = self.output_names or self.state_names
        idx = [self.state_names.index(o) for o in names]
        return names, self.states[:, idx] - self.x_op[idx]

    # -- files --------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write the run to an ``.npz`` file (lossless); returns the path written."""
        p = Path(path)
        if p.suffix == ".csv":
            return self.to_csv(p)
        if p.suffix != ".npz":
            p = p.with_name(p.name + ".npz")
        meta = {
            "format": FORMAT,
            "system": self.system,
            "params": dict(self.params),
            "state_names": list(self.state_names),
            "state_units": list(self.state_units),
            "input_names": list(self.input_names),
            "input_units": list(self.input_units),
            "output_names": list(self.output_names),
            "reference_names": list(self.reference_names),
            "fell": self.fell,
            "fell_at": None if self.fell_at is None else round(float(self.fell_at), 12),
            "fell_state": self.fell_state,
            "settings": dict(self.settings),
        }
        arrays = {name: getattr(self, name) for name in _ARRAYS if getattr(self, name) is not None}
        arrays.update(x_op=self.x_op, u_op=self.u_op, final_state=self.final_state)
        if self.fell_x is not None:
            arrays["fell_x"] = self.fell_x
        np.savez(p, meta=np.array(json.dumps(meta)), **arrays)
        return p

    @classmethod
    def load(cls, path: str | Path) -> SimResult:
        """Read a run written by :meth:`save`."""
        p = Path(path)
        if not p.exists():
            raise SimulationError(f"no result file {p}")
        try:
            with np.load(p, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                arrays = {k: data[k] for k in data.files if k != "meta"}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise SimulationError(f"{p} is not a saved simulation result: {exc}") from None
        if meta.get("format") != FORMAT:
            raise SimulationError(f"{p} is not a saved simulation result (format {meta.get('format')!r})")
        return cls(
            system=meta["system"],
            params=meta["params"],
            state_names=tuple(meta["state_names"]),
            state_units=tuple(meta["state_units"]),
            input_names=tuple(meta["input_names"]),
            input_units=tuple(meta["input_units"]),
            output_names=tuple(meta["output_names"]),
            reference_names=tuple(meta["reference_names"]),
            time=arrays["time"],
            states=arrays["states"],
            estimates=arrays.get("estimates"),
            measurements=arrays["measurements"],
            commanded=arrays["commanded"],
            saturated=arrays["saturated"],
            applied=arrays["applied"],
            reference=arrays["reference"],
            x_op=arrays["x_op"],
            u_op=arrays["u_op"],
            fell=bool(meta["fell"]),
            fell_at=meta["fell_at"],
            fell_state=meta["fell_state"],
            fell_x=arrays.get("fell_x"),
            final_state=arrays["final_state"],
            settings=meta["settings"],
        )

    def columns(self) -> list[tuple[str, str, np.ndarray]]:
        """``(column name, unit, values)`` of every recorded quantity, in CSV order."""
        cols: list[tuple[str, str, np.ndarray]] = [("time", "s", self.time)]
        for i, (n, u) in enumerate(zip(self.state_names, self.state_units, strict=True)):
            cols.append((n, u, self.states[:, i]))
        if self.estimates is not None:
            for i, (n, u) in enumerate(zip(self.state_names, self.state_units, strict=True)):
                cols.append((f"{n}_hat", u, self.estimates[:, i]))
        for i, n in enumerate(self.output_names):
            cols.append((f"{n}_measured", self.unit(n), self.measurements[:, i]))
        for i, (n, u) in enumerate(zip(self.input_names, self.input_units, strict=True)):
            cols.append((f"{n}_commanded", u, self.commanded[:, i]))
            cols.append((f"{n}_saturated", u, self.saturated[:, i]))
            cols.append((f"{n}", u, self.applied[:, i]))
        for i, n in enumerate(self.reference_names):
            cols.append((f"{n}_reference", self.unit(n), self.reference[:, i]))
        return cols

    def to_csv(self, path: str | Path) -> Path:
        """Write one column per quantity (header ``name [unit]``) with 17 significant digits."""
        p = Path(path)
        cols = self.columns()
        header = ",".join(f"{n} [{u}]" if u else n for n, u, _ in cols)
        data = np.column_stack([c[2] for c in cols]) if cols else np.zeros((0, 0))
        lines = [f"# {self.system}; fell: {self.fell}; fell_at: {self.fell_at}", header]
        lines += [",".join(_repr(v) for v in row) for row in data]
        p.write_text("\n".join(lines) + "\n")
        return p

    @staticmethod
    def read_csv(path: str | Path) -> dict[str, np.ndarray]:
        """The columns of a CSV written by :meth:`to_csv`, by name (units dropped)."""
        text = Path(path).read_text().splitlines()
        rows = [ln for ln in text if not ln.startswith("#")]
        names = [h.split(" [")[0] for h in rows[0].split(",")]
        data = np.array([[float(v) for v in ln.split(",")] for ln in rows[1:]]).reshape(-1, len(names))
        return {n: data[:, i] for i, n in enumerate(names)}


def _repr(v: float) -> str:
    if math.isnan(v):
        return "nan"
    return repr(float(v))
