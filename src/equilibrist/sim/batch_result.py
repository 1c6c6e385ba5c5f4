"""The outcome of a batch (:class:`BatchResult`): one row per run, a run's trajectory
on demand, the summary, and the ``.npz`` and ``.csv`` files it is saved to and read
back from; :func:`_batch_result` makes one from the core's per-run arrays."""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from equilibrist.atomic import atomic_path, write_text
from equilibrist.errors import SimulationError, nearest
from equilibrist.sim import layout, setup_data
from equilibrist.sim.noise import seed_from_description
from equilibrist.sim.result import SimResult, check_result_path, digest_field, read_npz
from equilibrist.sim.run import _result, fall_reason
from equilibrist.tasks import balance_criterion

# Format 2 adds the peak command beside the peak input applied.
FORMAT = "equilibrist-batch-2"


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Outcomes of many runs (arrays with one row per run).

    Attributes
    ----------
    x0 : ndarray, shape (runs, n_states)
        Initial states.
    params : ndarray, shape (runs, n_params)
        The plant's parameters of each run (``parameter_names`` order).
    fell, fell_at, fell_code :
        Whether each run fell, when (NaN if it did not), and the index of the
        state that left its region (-2 not finite, -3 integrator failed, -1 none).
    final_state, fell_x : ndarray, shape (runs, n_states)
    peak_input, rms_input : ndarray, shape (runs, n_inputs)
        Largest ``|input|`` applied (after the actuator's limits) and RMS of
        the applied input.
    peak_command : ndarray, shape (runs, n_inputs)
        Largest ``|command|`` (the controller's, before the limits).
    time_saturated : ndarray, shape (runs,)
    peak_deviation, estimation_error_rms : ndarray, shape (runs, n_states)
    rows : ndarray, shape (runs,)
        Samples recorded per run.
    trajectories : ndarray or None, shape (runs, n_rows, width)
        With ``record=True``: the packed rows (see :meth:`run`).
    elapsed : float
        Wall time of the compiled runs [s]; ``steps`` physics steps in all.
    """

    system: str
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    parameter_names: tuple[str, ...]
    x0: np.ndarray
    params: np.ndarray
    fell: np.ndarray
    fell_at: np.ndarray
    fell_code: np.ndarray
    fell_x: np.ndarray
    final_state: np.ndarray
    peak_input: np.ndarray
    peak_command: np.ndarray
    rms_input: np.ndarray
    time_saturated: np.ndarray
    peak_deviation: np.ndarray
    estimation_error_rms: np.ndarray | None
    rows: np.ndarray
    seeds: tuple[dict[str, object] | None, ...]
    settings: Mapping[str, object]
    elapsed: float = 0.0
    steps: int = 0
    trajectories: np.ndarray | None = None
    system_digest: str | None = None
    balanced_since: np.ndarray | None = None
    _setup: setup_data.Setup | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("x0", "params", "fell", "fell_at", "fell_code", "fell_x", "final_state",
                     "peak_input", "peak_command", "rms_input", "time_saturated",
                     "peak_deviation", "estimation_error_rms", "rows", "trajectories"):
            v = getattr(self, name)
            if v is not None:
                v = np.asarray(v)
                v.setflags(write=False)
                object.__setattr__(self, name, v)
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))

    def __repr__(self) -> str:
        return (f"BatchResult({self.system}, {self.runs} runs, {self.stayed_up} stayed up, "
                f"{self.steps_per_second / 1e6:.1f} M steps/s)")

    @property
    def runs(self) -> int:
        return int(self.fell.shape[0])

    @property
    def stayed_up(self) -> int:
        """How many runs stayed up."""
        return int(self.runs - np.count_nonzero(self.fell))

    @property
    def fraction_up(self) -> float:
        return self.stayed_up / self.runs if self.runs else math.nan

    @property
    def balanced(self) -> int:
        """How many runs ended balanced and stayed so (``balanced_since`` is a time)."""
        return 0 if self.balanced_since is None else int(np.count_nonzero(
            np.isfinite(self.balanced_since)))

    @property
    def fraction_balanced(self) -> float:
        """The share of runs that end in the balance box and stay in it to the end (the
        criterion: ``settings["balanced"]``, equilibrist.tasks.balance_box)."""
        if self.balanced_since is None or not self.runs:
            return math.nan
        return self.balanced / self.runs

    def time_to_balance(self, q: float) -> float | None:
        """The *q*-quantile (0..1) of the time from which the balanced runs stayed balanced."""
        if self.balanced_since is None:
            return None
        t = self.balanced_since[np.isfinite(self.balanced_since)]
        return float(np.quantile(t, q)) if t.size else None

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.elapsed if self.elapsed > 0 else math.inf

    def seed(self, index: int) -> np.random.SeedSequence | None:
        """The seed that reproduces run *index* alone with :func:`simulate`."""
        desc = self.seeds[index]
        return None if desc is None else seed_from_description(desc)

    def param(self, name: str) -> np.ndarray:
        """The values of parameter *name* over the runs."""
        if name not in self.parameter_names:
            raise SimulationError(f"no parameter {name!r}: {nearest(name, self.parameter_names)}")
        return self.params[:, self.parameter_names.index(name)]

    def fell_states(self) -> list[str | None]:
        """Per run, the state that left its region (None for runs that stayed up)."""
        return [fall_reason(int(c), self.state_names) if f else None
                for f, c in zip(self.fell, self.fell_code, strict=True)]

    def run(self, index: int) -> SimResult:
        """Run *index* as a :class:`SimResult` (needs ``record=True``)."""
        if self.trajectories is None or self._setup is None:
            raise SimulationError("the batch kept no trajectories: run it with record=True")
        if not 0 <= index < self.runs:
            raise SimulationError(f"run {index} out of range 0..{self.runs - 1}")
        setup = self._setup
        status = layout.STATUS.pack(
            np.int64, rows=self.rows[index], fell=int(self.fell[index]),
            fell_code=self.fell_code[index],
            fell_step=0 if not self.fell[index] else round(self.fell_at[index] / setup.h))
        sysm = setup.system.with_params(**dict(zip(self.parameter_names,
                                                   self.params[index].tolist(), strict=True)))
        s = setup_data.Setup(**{**setup.__dict__, "system": sysm, "x0": self.x0[index]})
        seq = self.seed(index)
        return _result(s, np.asarray(self.trajectories[index]), int(self.rows[index]), status,
                       np.asarray(self.fell_x[index]), np.asarray(self.final_state[index]), seq,
                       estimates=setup.estimates)

    def summary(self) -> dict[str, object]:
        """``runs``, ``stayed_up``, ``fraction_up``, ``steps_per_second`` and friends."""
        fell_at = self.fell_at[self.fell]
        criterion = self.settings.get("balanced", {})
        if not isinstance(criterion, Mapping):
            raise SimulationError(f"the batch's balanced criterion should be a mapping, found {criterion!r}")
        return {
            "system": self.system,
            "runs": self.runs,
            "stayed_up": self.stayed_up,
            # A count (a single run's "fell" is a flag: another name, another type).
            "fallen": int(np.count_nonzero(self.fell)),
            "fraction_up": self.fraction_up,
            "steps": int(self.steps),
            "elapsed": self.elapsed,
            "steps_per_second": self.steps_per_second,
            "fell_at_median": float(np.median(fell_at)) if fell_at.size else None,
            "peak_input_max": dict(zip(self.input_names, self.peak_input.max(axis=0).tolist(), strict=True)) if self.runs else {},
            "time_saturated_mean": float(self.time_saturated.mean()) if self.runs else None,
            # Runs that end balanced and stay (a swing-up's success: fraction_up only says
            # no run left its region), the time from which they stayed, and the criterion.
            "balanced": self.balanced,
            "fraction_balanced": self.fraction_balanced,
            "time_to_balance_median": self.time_to_balance(0.5),
            "time_to_balance_p90": self.time_to_balance(0.9),
            "balanced_criterion": dict(criterion),
        }

    def save(self, path: str | Path) -> Path:
        """Write the batch's per-run arrays to ``.npz`` (trajectories are not saved)."""
        p = Path(path)
        if p.suffix.lower() == ".csv":
            return self.to_csv(p)
        check_result_path(p, "a batch")
        meta = {
            "format": FORMAT, "system": self.system, "system_digest": self.system_digest,
            "state_names": list(self.state_names),
            "input_names": list(self.input_names), "parameter_names": list(self.parameter_names),
            "seeds": list(self.seeds), "settings": dict(self.settings), "elapsed": self.elapsed,
            "steps": self.steps,
        }
        arrays = {k: getattr(self, k) for k in (
            "x0", "params", "fell", "fell_at", "fell_code", "fell_x", "final_state", "peak_input",
            "peak_command",
            "rms_input", "time_saturated", "peak_deviation", "rows")}
        if self.estimation_error_rms is not None:
            arrays["estimation_error_rms"] = self.estimation_error_rms
        if self.balanced_since is not None:
            arrays["balanced_since"] = self.balanced_since
        with atomic_path(p) as tmp:
            np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays)
        return p

    def to_csv(self, path: str | Path) -> Path:
        """A table, one row per run: its initial state, parameters, outcome and metrics."""
        p = Path(path)
        cols: list[tuple[str, np.ndarray]] = [("run", np.arange(self.runs, dtype=float))]
        cols += [(f"{n}_0", self.x0[:, i]) for i, n in enumerate(self.state_names)]
        cols += [(n, self.params[:, i]) for i, n in enumerate(self.parameter_names)]
        cols += [("fell", self.fell.astype(float)), ("fell_at", self.fell_at)]
        cols += [(f"peak_{n}", self.peak_input[:, i]) for i, n in enumerate(self.input_names)]
        cols += [(f"peak_command_{n}", self.peak_command[:, i]) for i, n in enumerate(self.input_names)]
        cols += [(f"rms_{n}", self.rms_input[:, i]) for i, n in enumerate(self.input_names)]
        cols += [("time_saturated", self.time_saturated)]
        cols += [(f"peak_dev_{n}", self.peak_deviation[:, i]) for i, n in enumerate(self.state_names)]
        lines = [f"# {self.system}: {self.runs} runs; fell_at is nan for a run that stayed up",
                 ",".join(n for n, _ in cols)]
        table = np.column_stack([np.asarray(v, dtype=float).reshape(self.runs) for _, v in cols])
        lines += [",".join("nan" if math.isnan(v) else repr(float(v)) for v in row) for row in table]
        write_text(p, "\n".join(lines) + "\n")
        return p

    @classmethod
    def load(cls, path: str | Path) -> BatchResult:
        """Read a batch written by :meth:`save`."""
        p = Path(path)
        try:
            meta, arrays = read_npz(p)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise SimulationError(f"{p} is not a saved batch: {exc}") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            found = meta.get("format") if isinstance(meta, dict) else None
            raise SimulationError(f"{p} is not a saved batch of this version (format {found!r}, "
                                  f"expected {FORMAT!r}): run the batch again")
        _check_batch_file(p, meta, arrays)
        return cls(
            system=meta["system"], state_names=tuple(meta["state_names"]),
            input_names=tuple(meta["input_names"]),
            parameter_names=tuple(meta["parameter_names"]),
            estimation_error_rms=arrays.pop("estimation_error_rms", None),
            seeds=tuple(meta["seeds"]), settings=meta["settings"], elapsed=meta["elapsed"],
            steps=meta["steps"], system_digest=digest_field(meta, f"{p} is not a valid saved batch"),
            _setup=None, **arrays,
        )


_BATCH_ARRAYS = ("x0", "params", "fell", "fell_at", "fell_code", "fell_x", "final_state",
                 "peak_input", "peak_command", "rms_input", "time_saturated", "peak_deviation",
                 "rows")


def _check_batch_file(p: Path, meta: dict[str, object], arrays: dict[str, np.ndarray]) -> None:
    """Refuse a batch file whose contents are not what :meth:`BatchResult.save` writes."""
    bad = f"{p} is not a valid saved batch"
    for key in ("state_names", "input_names", "parameter_names"):
        v = meta.get(key)
        if not isinstance(v, list) or not all(isinstance(n, str) for n in v):
            raise SimulationError(f"{bad}: {key} should be a list of names")
    if not isinstance(meta.get("system"), str) or not isinstance(meta.get("settings"), dict):
        raise SimulationError(f"{bad}: system and settings are missing or of the wrong type")
    if not isinstance(meta.get("seeds"), list):
        raise SimulationError(f"{bad}: seeds should be a list")
    for key in ("elapsed", "steps"):
        if not isinstance(meta.get(key), (int, float)) or isinstance(meta.get(key), bool):
            raise SimulationError(f"{bad}: {key} should be a number")
    missing = [k for k in _BATCH_ARRAYS if k not in arrays]
    if missing:
        raise SimulationError(f"{bad}: the arrays {', '.join(missing)} are missing")
    runs = arrays["x0"].shape[0] if arrays["x0"].ndim == 2 else -1
    for key, a in arrays.items():
        if a.dtype.kind not in "fiub" or a.ndim == 0 or a.shape[0] != runs:
            raise SimulationError(f"{bad}: {key} is not one row of numbers per run")


def _balanced_since(last_out: np.ndarray, fell: np.ndarray, rows: np.ndarray,
                    setup: setup_data.Setup) -> np.ndarray:
    """Per run, the time from which its state stayed in the balance box to the end
    (equilibrist.tasks.balance_box), NaN for a run that fell or did not end in it."""
    ended_in = ~fell & (last_out < rows)
    return np.where(ended_in, last_out / setup.rate, np.nan)


def _batch_result(setup: setup_data.Setup, x0s: np.ndarray, pmat: np.ndarray,
                  seeds: Sequence[dict[str, object] | None], statuses: np.ndarray,
                  accs: np.ndarray, fell_xs: np.ndarray, x_ends: np.ndarray,
                  recs: np.ndarray | None, elapsed: float) -> BatchResult:
    """The batch's result; *seeds*: each run's :func:`~equilibrist.sim.noise.describe_seed`."""
    sysm = setup.system
    st = layout.STATUS
    acc = layout.ACC.slices(**setup.sizes)
    rows = statuses[:, st["rows"]]
    fell = statuses[:, st["fell"]].astype(bool)
    fell_at = np.where(fell, statuses[:, st["fell_step"]] * setup.h, np.nan)
    code = np.where(fell, statuses[:, st["fell_code"]], -1)
    steps_done = np.where(fell, statuses[:, st["fell_step"]], setup.n_samples * setup.n_sub)
    settings = setup.describe()
    settings["x0"] = None
    settings["balanced"] = balance_criterion(sysm)
    count = np.maximum(rows, 1)[:, None]
    return BatchResult(
        system=sysm.key, system_digest=sysm.digest, state_names=sysm.state_names,
        input_names=sysm.input_names, parameter_names=sysm.spec.parameter_names, x0=x0s, params=pmat, fell=fell,
        fell_at=fell_at, fell_code=code, fell_x=fell_xs, final_state=x_ends,
        peak_input=accs[:, acc["peak_u_app"]], peak_command=accs[:, acc["peak_u"]],
        rms_input=np.sqrt(accs[:, acc["sum_u2"]] / count),
        time_saturated=accs[:, acc["n_sat"].start] / setup.rate,
        peak_deviation=accs[:, acc["peak_dx"]],
        estimation_error_rms=(np.sqrt(accs[:, acc["sum_est2"]] / count)
                              if setup.estimates else None),
        balanced_since=_balanced_since(accs[:, acc["last_out"].start], fell, rows, setup),
        rows=rows, seeds=tuple(seeds),
        settings=settings, elapsed=elapsed, steps=int(steps_done.sum()), trajectories=recs,
        _setup=setup,
    )
