"""The result of a simulated run: named, time-major arrays, the settings, the metrics.

Rows are the controller's samples ``t_k = k T``: row ``k`` holds the true
state at ``t_k``, the measurement taken then, the controller's estimate and
command, and the input applied from ``t_k`` to ``t_k+1``. A run that fell
stops at the last sample before the fall; ``fell_at`` is the time (on the
physics grid) at which a state left the system's region.

A result saves to ``.npz`` (lossless: the arrays bit for bit, the settings as
JSON) and exports to CSV (one column per named quantity, unit in the header,
17 significant digits, the settings as JSON in a comment line, so the CSV is
lossless too and loads back). The CSV starts with the columns of a rig's
log, as ``equilibrist identify`` reads it: ``t``, the inputs that acted (named
as the system names them) and the measured outputs (named after the states
they measure); the true states follow as ``<state>_true``, then the
estimates (``_hat``), the commands (``_commanded``, ``_saturated``) and the
references (``_reference``).
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import SupportsFloat, TypedDict

import numpy as np

from equilibrist.atomic import atomic_path, write_text
from equilibrist.errors import SimulationError, UnknownNameError, nearest

FORMAT = "equilibrist-simresult-1"
#: An output's overshoot is None when its initial error is at most this share of its
#: largest error in the run (:meth:`SimResult.metrics`): it starts as good as on target.
OVERSHOOT_FLOOR = 1e-6

_ARRAYS = ("time", "states", "estimates", "measurements", "commanded", "saturated", "applied",
           "reference")


def _names(label: str, names: tuple[str, ...], name: str) -> int:
    if name not in names:
        if not names:
            raise UnknownNameError(f"the run has no {label}s (asked for {name!r})")
        raise UnknownNameError(f"no {label} {name!r}: {nearest(name, names)}")
    return names.index(name)


class RunMetrics(TypedDict):
    """What :meth:`SimResult.metrics` returns (see there)."""

    system: str
    fell: bool
    fell_at: float | None
    fell_state: str | None
    stayed_up: bool
    duration: float
    settling_time: float | None
    overshoot: dict[str, float | None]
    peak_command: dict[str, float]
    peak_input: dict[str, float]
    rms_input: dict[str, float]
    time_saturated: float
    final_error: dict[str, float]
    estimation_error_rms: dict[str, float] | None
    peak_deviation: dict[str, float]
    seed: object


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
    system_digest : str or None
        SHA-256 of the system's definition when it came from a file
        (:attr:`~equilibrist.numeric.system.System.digest`): a reader handed a
        system checks it is this one.
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
    settings: Mapping[str, object] = field(default_factory=dict)
    system_digest: str | None = None

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
        rate = self.settings["rate"]
        if not isinstance(rate, SupportsFloat | str):
            raise SimulationError(f"the run's rate {rate!r} is not a number")
        return 1.0 / float(rate)

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
    def metrics(self, *, settle_fraction: float = 0.02) -> RunMetrics:
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
        error: the size of the move the output makes to its target. None
        for an output that starts on target or as good as on it, its initial
        error at most :data:`OVERSHOOT_FLOOR` (one millionth) of its largest
        error in the run (such as a cart that a swing-up starts 1e-32 m off
        centre: a fraction of so small a move is round-off, not a measure).
        ``peak_command``: the largest ``|command|`` (the controller's, before
        the actuator's limits); ``peak_input``: the largest ``|input|``
        applied; ``rms_input``: RMS of the applied input (all absolute, per
        input); ``time_saturated``: time
        with any command outside its limits [s]; ``final_error``: watched
        output minus target at the end; ``estimation_error_rms``: RMS of
        estimate minus truth per state (None without estimate).
        """
        if not 0 < settle_fraction < 1:
            raise SimulationError(f"settle_fraction must be in (0, 1), got {settle_fraction}")
        if not self.n_rows:  # ended before its first sample (a device's fault): no figures
            return self._no_metrics()
        dt = self.dt
        watched, errors = self._watched_errors()
        overshoot: dict[str, float | None] = {}
        settle_idx = 0
        settled = True
        for j, name in enumerate(watched):
            e = errors[:, j]
            e0 = e[0]
            if abs(e0) > OVERSHOOT_FLOOR * float(np.abs(e).max()):
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
            "peak_command": dict(zip(self.input_names, np.abs(self.commanded).max(axis=0).tolist(), strict=True)),
            "peak_input": dict(zip(self.input_names, np.abs(self.applied).max(axis=0).tolist(), strict=True)),
            "rms_input": dict(zip(self.input_names, np.sqrt(np.mean(self.applied**2, axis=0)).tolist(), strict=True)),
            # Samples whose command was clipped, times the sample period (the
            # compiled batch counts the same way, the last sample included).
            "time_saturated": float(np.count_nonzero(sat_rows) * dt),
            "final_error": dict(zip(watched, errors[-1].tolist(), strict=True)),
            "estimation_error_rms": est_rms,
            "peak_deviation": dict(zip(self.state_names, np.abs(self.states - self.x_op).max(axis=0).tolist(), strict=True)),
            "seed": self.settings.get("seed"),
        }

    def _no_metrics(self) -> RunMetrics:
        """:meth:`metrics` of a run with no sample: no figure per output, input or state."""
        return {"system": self.system, "fell": bool(self.fell), "fell_at": self.fell_at,
                "fell_state": self.fell_state, "stayed_up": not self.fell, "duration": 0.0,
                "settling_time": None, "overshoot": {}, "peak_command": {}, "peak_input": {},
                "rms_input": {}, "time_saturated": 0.0, "final_error": {},
                "estimation_error_rms": None, "peak_deviation": {},
                "seed": self.settings.get("seed")}

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
        if p.suffix.lower() == ".csv":
            return self.to_csv(p)
        check_result_path(p, "a run")
        meta = self._meta()
        arrays = {name: getattr(self, name) for name in _ARRAYS if getattr(self, name) is not None}
        arrays.update(x_op=self.x_op, u_op=self.u_op, final_state=self.final_state)
        if self.fell_x is not None:
            arrays["fell_x"] = self.fell_x
        with atomic_path(p) as tmp:
            np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays)
        return p

    def _meta(self) -> dict[str, object]:
        return {
            "format": FORMAT,
            "system": self.system,
            "system_digest": self.system_digest,
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

    @classmethod
    def load(cls, path: str | Path) -> SimResult:
        """Read a run written by :meth:`save` (``.npz``, or ``.csv`` by :meth:`to_csv`)."""
        p = Path(path)
        if not p.exists():
            raise SimulationError(f"no result file {p}")
        try:
            meta, arrays = read_csv_result(p) if p.suffix.lower() == ".csv" else read_npz(p)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise SimulationError(f"{p} is not a saved simulation result: {exc}") from None
        return _checked(cls, meta, arrays, p)

    def columns(self) -> list[tuple[str, str, np.ndarray]]:
        """``(column name, unit, values)`` of every recorded quantity, in CSV order.

        First the run's log as a rig records it (``t``, the inputs that acted,
        the measured outputs), then the true states and the rest.
        """
        cols: list[tuple[str, str, np.ndarray]] = [("t", "s", self.time)]
        for i, (n, u) in enumerate(zip(self.input_names, self.input_units, strict=True)):
            cols.append((n, u, self.applied[:, i]))
        for i, n in enumerate(self.output_names):
            cols.append((n, self.unit(n), self.measurements[:, i]))
        for i, (n, u) in enumerate(zip(self.state_names, self.state_units, strict=True)):
            cols.append((f"{n}_true", u, self.states[:, i]))
        if self.estimates is not None:
            for i, (n, u) in enumerate(zip(self.state_names, self.state_units, strict=True)):
                cols.append((f"{n}_hat", u, self.estimates[:, i]))
        for i, (n, u) in enumerate(zip(self.input_names, self.input_units, strict=True)):
            cols.append((f"{n}_commanded", u, self.commanded[:, i]))
            cols.append((f"{n}_saturated", u, self.saturated[:, i]))
        for i, n in enumerate(self.reference_names):
            cols.append((f"{n}_reference", self.unit(n), self.reference[:, i]))
        return cols

    def to_csv(self, path: str | Path) -> Path:
        """Write one column per quantity (header ``name [unit]``) with 17 significant digits.

        A comment line holds the rest of the result as JSON, so that
        :meth:`load` reads the file back.
        """
        p = Path(path)
        cols = self.columns()
        header = ",".join(f"{n} [{u}]" if u else n for n, u, _ in cols)
        data = np.column_stack([c[2] for c in cols]) if cols else np.zeros((0, 0))
        meta = self._meta()
        meta["csv"] = {"x_op": self.x_op.tolist(), "u_op": self.u_op.tolist(),
                       "final_state": self.final_state.tolist(),
                       "fell_x": None if self.fell_x is None else self.fell_x.tolist(),
                       "estimates": self.estimates is not None}
        lines = [f"# {self.system}; fell: {self.fell}; fell_at: {self.fell_at}",
                 f"# {json.dumps(meta)}", header]
        lines += [",".join(_repr(v) for v in row) for row in data]
        write_text(p, "\n".join(lines) + "\n")
        return p

    @staticmethod
    def read_csv(path: str | Path) -> dict[str, np.ndarray]:
        """The columns of a CSV written by :meth:`to_csv`, by name (units dropped).

        The time is also given as ``"time"``, its column's name in earlier files.
        """
        text = Path(path).read_text().splitlines()
        rows = [ln for ln in text if not ln.startswith("#")]
        names = [h.split(" [")[0] for h in rows[0].split(",")]
        data = np.array([[float(v) for v in ln.split(",")] for ln in rows[1:]]).reshape(-1, len(names))
        cols = {n: data[:, i] for i, n in enumerate(names)}
        if "t" in cols and "time" not in cols:
            cols["time"] = cols["t"]
        return cols


def _repr(v: float) -> str:
    if math.isnan(v):
        return "nan"
    return repr(float(v))


def read_csv_result(path: Path) -> tuple[object, dict[str, np.ndarray]]:
    """``(meta, arrays)`` of a CSV written by :meth:`SimResult.to_csv`.

    Raises ValueError or KeyError on a CSV that is not one.
    """
    with path.open(errors="replace") as fh:
        head = [fh.readline() for _ in range(2)]
    line = next((h for h in head if h.startswith("# {")), None)
    if line is None:
        raise ValueError("no result line at its top (a CSV written by equilibrist has one)")
    meta = json.loads(line[2:])
    extra = meta.pop("csv")
    cols = SimResult.read_csv(path)
    n_rows = cols["t"].shape[0]

    def block(names: list[str], suffix: str) -> np.ndarray:
        if not names:
            return np.zeros((n_rows, 0))
        return np.column_stack([cols[f"{n}{suffix}"] for n in names])

    arrays = {
        "time": cols["t"],
        "states": block(meta["state_names"], "_true"),
        "measurements": block(meta["output_names"], ""),
        "commanded": block(meta["input_names"], "_commanded"),
        "saturated": block(meta["input_names"], "_saturated"),
        "applied": block(meta["input_names"], ""),
        "reference": block(meta["reference_names"], "_reference"),
        "x_op": np.array(extra["x_op"], dtype=float),
        "u_op": np.array(extra["u_op"], dtype=float),
        "final_state": np.array(extra["final_state"], dtype=float),
    }
    if extra["estimates"]:
        arrays["estimates"] = block(meta["state_names"], "_hat")
    if extra["fell_x"] is not None:
        arrays["fell_x"] = np.array(extra["fell_x"], dtype=float)
    return meta, arrays


def read_npz(path: Path) -> tuple[object, dict[str, np.ndarray]]:
    """``(meta, arrays)`` of a result file; never unpickles, never leaks the file handle.

    Raises what numpy, zipfile and json raise on a file that is not one.
    """
    with path.open("rb") as fh, np.load(fh, allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
        arrays = {k: data[k] for k in data.files if k != "meta"}
    return meta, arrays


def check_result_path(path: Path, what: str, suffixes: tuple[str, ...] = (".npz", ".csv")) -> None:
    """Refuse a result file name that is empty or has a suffix no writer knows."""
    if not str(path) or not path.name or path.name in (".", ".."):
        raise SimulationError(f"the file to save {what} in has no name: expected NAME{suffixes[0]}")
    if path.suffix.lower() not in suffixes:
        raise SimulationError(
            f"{path}: unknown result format {path.suffix or '(no suffix)'!r}: expected "
            + " or ".join(suffixes)
        )


def _checked(cls: type[SimResult], meta: object, arrays: dict[str, np.ndarray], p: Path) -> SimResult:
    """A :class:`SimResult` from a file's contents, every field checked once, here."""
    bad = f"{p} is not a valid saved simulation result"
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise SimulationError(f"{p} is not a saved simulation result (format {found!r})")

    def text(key: str, *, optional: bool = False) -> str | None:
        v = meta.get(key)
        if v is None and optional:
            return None
        if not isinstance(v, str):
            raise SimulationError(f"{bad}: {key} should be text, found {v!r}")
        return v

    def names(key: str) -> tuple[str, ...]:
        v = meta.get(key)
        if not isinstance(v, list) or not all(isinstance(n, str) for n in v):
            raise SimulationError(f"{bad}: {key} should be a list of names, found {v!r}")
        return tuple(v)

    def maybe(key: str, shape: tuple[int | None, ...], *, finite: bool = True) -> np.ndarray | None:
        return array(key, shape, finite=finite) if key in arrays else None

    def array(key: str, shape: tuple[int | None, ...], *, finite: bool = True) -> np.ndarray:
        if key not in arrays:
            raise SimulationError(f"{bad}: the array {key!r} is missing")
        a = arrays[key]
        if a.dtype.kind not in "fiub":
            raise SimulationError(f"{bad}: {key} holds {a.dtype} values, expected numbers")
        a = a.astype(float)
        if a.ndim != len(shape) or any(w is not None and w != n for w, n in zip(shape, a.shape, strict=True)):
            want = "x".join("n" if w is None else str(w) for w in shape)
            raise SimulationError(f"{bad}: {key} has shape {a.shape}, expected {want}")
        if finite and not np.all(np.isfinite(a)):
            raise SimulationError(f"{bad}: {key} holds values that are not finite numbers")
        return a

    system = text("system")
    params = meta.get("params")
    if not isinstance(params, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) for k, v in params.items()
    ):
        raise SimulationError(f"{bad}: params should map names to numbers")
    states_n = names("state_names")
    inputs_n = names("input_names")
    outputs_n = names("output_names")
    refs_n = names("reference_names")
    state_units = names("state_units")
    input_units = names("input_units")
    if len(state_units) != len(states_n) or len(input_units) != len(inputs_n):
        raise SimulationError(f"{bad}: units do not match the names")
    time = array("time", (None,))
    rows = time.shape[0]
    if rows == 0 or np.any(np.diff(time) <= 0):
        raise SimulationError(f"{bad}: time must be a non-empty increasing sequence")
    n, m = len(states_n), len(inputs_n)
    fell = meta.get("fell")
    fell_at = meta.get("fell_at")
    if not isinstance(fell, bool):
        raise SimulationError(f"{bad}: fell should be true or false, found {fell!r}")
    if fell_at is not None and (not isinstance(fell_at, (int, float)) or not math.isfinite(fell_at)):
        raise SimulationError(f"{bad}: fell_at should be a time in seconds, found {fell_at!r}")
    settings = meta.get("settings")
    if not isinstance(settings, dict):
        raise SimulationError(f"{bad}: settings should be a mapping, found {settings!r}")
    return cls(
        system=str(system),
        params={k: float(v) for k, v in params.items()},
        state_names=states_n,
        state_units=state_units,
        input_names=inputs_n,
        input_units=input_units,
        output_names=outputs_n,
        reference_names=refs_n,
        time=time,
        states=array("states", (rows, n)),
        estimates=maybe("estimates", (rows, n)),
        measurements=array("measurements", (rows, len(outputs_n))),
        commanded=array("commanded", (rows, m)),
        saturated=array("saturated", (rows, m)),
        applied=array("applied", (rows, m)),
        reference=array("reference", (rows, len(refs_n))),
        x_op=array("x_op", (n,)),
        u_op=array("u_op", (m,)),
        fell=fell,
        fell_at=None if fell_at is None else float(fell_at),
        fell_state=text("fell_state", optional=True),
        fell_x=maybe("fell_x", (n,), finite=False),
        final_state=array("final_state", (n,), finite=False),
        settings=settings,
        system_digest=digest_field(meta, bad),
    )


def digest_field(meta: Mapping[str, object], bad: str) -> str | None:
    """The recorded ``system_digest`` of a file's metadata (a SHA-256 in hex), or ``None``."""
    v = meta.get("system_digest")
    if v is None:
        return None
    if not isinstance(v, str) or len(v) != 64 or any(c not in "0123456789abcdef" for c in v):
        raise SimulationError(f"{bad}: system_digest should be a SHA-256 in hex, found {str(v)[:80]!r}")
    return v
