"""What a study is: the quantities varied, the points, the runs per point.

A study is a grid (every combination of the varied quantities' values) or
a random sample (``sample = N`` points drawn uniformly within the ranges)
over any mix of

=====================  =============================================================
name                   what varies
=====================  =============================================================
a parameter (``m_p``)  the plant's physical parameter (validated against its range)
``rate``               the controller's sample rate [Hz] (design and simulation)
``q.<state>``          Bryson scale of a state: its largest acceptable deviation, in
                       the state's unit; the LQR weight is ``1 / scale**2``
``r.<input>``          Bryson scale of an input, in the input's unit
``controller``         a controller kind offered to studies (``lqr``, ``lqg``, ``mpc``,
                       ``swingup``, a kind of one's own: :mod:`equilibrist.control.kinds`)
``noise``              scale of the noise's standard deviations (0 = no noise; the
                       design keeps the spec's covariances)
``delay``              0 or 1: each command applied one sample late
=====================  =============================================================

times ``runs`` closed-loop runs per point (initial states uniform in the
``x0`` ranges, parameters uniform within ``nominal * (1 +- spread)`` around
the point's values, process and sensor noise).

Values on the command line: ``NAME=LOW:HIGH:N`` (N values evenly spaced,
both ends included), ``NAME=LOW:HIGH:N:log`` (geometrically spaced),
``NAME=V1,V2,...`` (a list) or ``NAME=V``. With ``sample = N`` a range is
``NAME=LOW:HIGH`` (``:log`` draws log-uniformly) and a list is drawn from
with equal chances.

Determinism: everything random in point ``i`` comes from
``numpy.random.SeedSequence(seed, spawn_key=(i, k))`` (``k = 0`` the
point's values in a random sample, ``1`` its initial states and spread,
``2, b`` the noise of its ``b``-th batch of ``batch_size`` runs, ``3`` the
region-of-attraction grid's noise): never from the worker, the chunk or the
order in which points finish.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from equilibrist.errors import EquilibristError, nearest

FORMAT = "equilibrist-study-1"
#: The project's own kinds a study takes (the registry may offer more: :func:`controllers`).
CONTROLLERS = ("lqr", "lqg", "swingup", "mpc")


def _does_not_apply(kind: str, system: Any) -> str | None:
    from equilibrist.control import kinds

    return kinds.get(kind).applies(system)


def controllers() -> tuple[str, ...]:
    """The controller kinds a study takes (:mod:`equilibrist.control.kinds`, surface ``study``)."""
    from equilibrist.control import kinds

    return kinds.names("study")
SPECIAL = ("rate", "controller", "noise", "delay")
DESIGN_FOR = ("point", "nominal")
METRICS = ("full", "basic")
# Samples kept in memory per batch (runs x rows x columns) for the
# trajectory metrics: about 32 MB of doubles.
BATCH_CELLS = 4_000_000
MAX_POINTS = 10_000_000
# Initial states of a point's region-of-attraction grid (the product of its N's): each
# is a run of every point, and the grid is allocated whole.
MAX_ROA_STATES = 100_000
# Samples of one run at most (a day at 100 Hz): a longer run is no study's, and its
# length would overflow the batch's sizing.
MAX_RUN_SAMPLES = 10_000_000


class StudyError(EquilibristError, ValueError):
    """A study that cannot be run as described."""


@dataclass(frozen=True)
class Axis:
    """One varied quantity.

    Attributes
    ----------
    name : str
        As written: ``m_p``, ``rate``, ``q.theta``, ``controller``, ...
    kind : str
        ``parameter``, ``rate``, ``q``, ``r``, ``controller``, ``noise`` or ``delay``.
    values : tuple
        The grid's values (a random sample's list to draw from), or empty
        for a range of a random sample.
    low, high : float or None
        The range of a random sample (None for a list).
    log : bool
        Geometric spacing (grid) or log-uniform draws (sample).
    """

    name: str
    kind: str
    values: tuple[Any, ...]
    low: float | None = None
    high: float | None = None
    log: bool = False

    @property
    def target(self) -> str:
        """The state, input or parameter the axis acts on (its name for the others)."""
        return self.name.split(".", 1)[1] if self.kind in ("q", "r") else self.name

    @property
    def is_text(self) -> bool:
        return self.kind == "controller"

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "values": list(self.values),
                "low": self.low, "high": self.high, "log": self.log}


@dataclass(frozen=True)
class Study:
    """A complete, validated study description (build it with :func:`make_study`).

    Everything that shapes the table is here and in :meth:`to_dict` (the
    file's metadata); how it is run (where, how many workers, chunking)
    is not, and never changes the table.
    """

    system: str
    settings: Mapping[str, Any]
    axes: tuple[Axis, ...]
    sample: int | None
    runs: int
    duration: float
    x0: Mapping[str, tuple[float, float]]
    spread: Mapping[str, float]
    seed: int
    controller: str
    noise: float
    delay: bool
    rate: float
    design_for: str
    metrics: str
    roa: Mapping[str, tuple[float, float, int]]
    batch_size: int

    # -- points -----------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        if self.sample is not None:
            return self.sample
        return math.prod(len(a.values) for a in self.axes) if self.axes else 1

    @property
    def total_runs(self) -> int:
        return self.n_points * self.runs

    def point(self, index: int) -> dict[str, Any]:
        """The varied quantities' values at point *index* (in axis order)."""
        if not 0 <= index < self.n_points:
            raise StudyError(f"point {index} out of range 0..{self.n_points - 1}")
        if self.sample is None:
            shape = [len(a.values) for a in self.axes]
            idx = np.unravel_index(index, shape) if shape else ()
            return {a.name: a.values[int(i)] for a, i in zip(self.axes, idx, strict=True)}
        gen = np.random.default_rng(self.point_seed(index, 0))
        out: dict[str, Any] = {}
        for a in self.axes:
            if a.values:
                out[a.name] = a.values[int(gen.integers(len(a.values)))]
            else:
                lo, hi = float(a.low), float(a.high)  # type: ignore[arg-type]
                u = float(gen.random())
                out[a.name] = (math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))
                               if a.log else lo + u * (hi - lo))
        return out

    def point_seed(self, index: int, *key: int) -> np.random.SeedSequence:
        """The seed of point *index*'s draws of kind *key* (see the module docstring)."""
        return np.random.SeedSequence(self.seed, spawn_key=(int(index), *map(int, key)))

    # -- description ----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "system": self.system,
            "set": dict(self.settings),
            "vary": [a.to_dict() for a in self.axes],
            "sample": self.sample,
            "runs": self.runs,
            "duration": self.duration,
            "x0": {k: list(v) for k, v in self.x0.items()},
            "spread": dict(self.spread),
            "seed": self.seed,
            "controller": self.controller,
            "noise": self.noise,
            "delay": self.delay,
            "rate": self.rate,
            "design_for": self.design_for,
            "metrics": self.metrics,
            "roa": {k: list(v) for k, v in self.roa.items()},
            "batch_size": self.batch_size,
        }

    def to_json(self) -> str:
        """The canonical description (sorted keys): what the file's metadata holds."""
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    @property
    def digest(self) -> str:
        return hashlib.sha256(self.to_json().encode()).hexdigest()

    @classmethod
    def from_json(cls, text: str) -> Study:
        """The study of :meth:`to_json` (as recorded in a table's metadata)."""
        d = json.loads(text)
        if d.get("format") != FORMAT:
            raise StudyError(f"not a study description of format {FORMAT}")
        return _from_description(d)


def _from_description(d: Mapping[str, Any]) -> Study:
    axes = tuple(Axis(a["name"], a["kind"], tuple(a["values"]), a["low"], a["high"], a["log"])
                 for a in d["vary"])
    return Study(
        system=d["system"], settings=dict(d["set"]), axes=axes, sample=d["sample"],
        runs=int(d["runs"]), duration=float(d["duration"]),
        x0={k: (float(v[0]), float(v[1])) for k, v in d["x0"].items()},
        spread={k: float(v) for k, v in d["spread"].items()}, seed=int(d["seed"]),
        controller=d["controller"], noise=float(d["noise"]), delay=bool(d["delay"]),
        rate=float(d["rate"]), design_for=d["design_for"], metrics=d["metrics"],
        roa={k: (float(v[0]), float(v[1]), int(v[2])) for k, v in d["roa"].items()},
        batch_size=int(d["batch_size"]),
    )


# -- building and checking ---------------------------------------------------------------


def _number(value: object, what: str, problems: list[str]) -> float | None:
    if isinstance(value, bool):
        problems.append(f"{what}: {value!r} is not a number")
        return None
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        problems.append(f"{what}: {value!r} is not a number")
        return None
    if not math.isfinite(v):
        problems.append(f"{what}: {value!r} is not a finite number")
        return None
    return v


def _whole(value: object, what: str, problems: list[str], *, minimum: int = 1) -> int | None:
    if isinstance(value, bool):
        problems.append(f"{what}: expected a whole number >= {minimum}, got {value!r}")
        return None
    try:
        v = int(str(value).strip()) if not isinstance(value, int) else value
    except ValueError:
        problems.append(f"{what}: expected a whole number >= {minimum}, got {value!r}")
        return None
    if v < minimum:
        problems.append(f"{what}: expected a whole number >= {minimum}, got {v}")
        return None
    return v


def _parse_values(name: str, value: object, sampled: bool, problems: list[str]
                  ) -> tuple[tuple[Any, ...], float | None, float | None, bool] | None:
    """``(values, low, high, log)`` of an axis from its text, list or table."""
    what = f"--vary {name}"
    if isinstance(value, Mapping):  # TOML {low = .., high = .., n = .., log = ..}
        unknown = sorted(set(value) - {"low", "high", "n", "log"})
        if unknown:
            problems.append(f"{what}: unknown key(s) {', '.join(unknown)} (expected low, high, n, log)")
            return None
        pieces = [value.get("low"), value.get("high")]
        if "n" in value:
            pieces.append(value["n"])
        if value.get("log"):
            pieces.append("log")
        text = ":".join("" if p is None else str(p) for p in pieces)
        return _parse_values(name, text, sampled, problems)
    if isinstance(value, (list, tuple)):
        if not value:
            problems.append(f"{what}: the list of values is empty")
            return None
        return tuple(value), None, None, False
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (value,), None, None, False
    text = str(value).strip()
    if not text:
        problems.append(f"{what}: no values (expected LOW:HIGH:N, V1,V2,... or V)")
        return None
    if ":" not in text:
        items = [t.strip() for t in text.split(",")]
        if not all(items):
            problems.append(f"{what}={text}: expected comma-separated values")
            return None
        return tuple(items), None, None, False
    parts = [t.strip() for t in text.split(":")]
    log = False
    if parts and parts[-1].lower() == "log":
        log = True
        parts = parts[:-1]
    form = "LOW:HIGH[:log]" if sampled else "LOW:HIGH:N[:log]"
    if len(parts) != (2 if sampled else 3):
        extra = (" (a random sample draws its own points: give the range only)"
                 if sampled and len(parts) == 3 else "")
        problems.append(f"{what}={text}: expected {form}{extra}")
        return None
    before = len(problems)
    lo = _number(parts[0], f"{what} LOW", problems)
    hi = _number(parts[1], f"{what} HIGH", problems)
    count = None if sampled else _whole(parts[2], f"{what} N", problems)
    if len(problems) > before or lo is None or hi is None:
        return None
    if lo > hi:
        problems.append(f"{what}={text}: reversed range, LOW {lo:g} is above HIGH {hi:g}")
        return None
    if lo == hi:
        problems.append(f"{what}={text}: empty range, LOW equals HIGH (give one value as {name}={lo:g})")
        return None
    if log and lo <= 0:
        problems.append(f"{what}={text}: a log range needs LOW > 0")
        return None
    if sampled:
        return (), lo, hi, log
    assert count is not None
    if count > MAX_POINTS:  # refused before the grid is allocated
        problems.append(f"{what}={text}: N = {count} values, at most {MAX_POINTS} per study")
        return None
    grid = np.geomspace(lo, hi, count) if log else np.linspace(lo, hi, count)
    return tuple(float(v) for v in grid), lo, hi, log


def _axis(system: Any, name: str, value: object, sampled: bool, problems: list[str]) -> Axis | None:
    spec = system.spec
    params = {p.name: p for p in spec.all_parameters}
    if name in params:
        kind = "parameter"
    elif name in SPECIAL:
        kind = name
    elif name.startswith(("q.", "r.")):
        kind = name[0]
        target = name[2:]
        names = system.state_names if kind == "q" else system.input_names
        if target not in names:
            what = "state" if kind == "q" else "input"
            problems.append(f"--vary {name}: {system.key} has no {what} {target!r} "
                            f"({nearest(target, names)})")
            return None
    else:
        choices = [*spec.parameter_names, *SPECIAL, *(f"q.{s}" for s in system.state_names),
                   *(f"r.{i}" for i in system.input_names)]
        problems.append(f"--vary: unknown quantity {name!r} of {system.key} ({nearest(name, choices)})")
        return None
    parsed = _parse_values(name, value, sampled, problems)
    if parsed is None:
        return None
    raw, low, high, log = parsed
    before = len(problems)
    values: list[Any] = []
    if kind == "controller":
        for v in raw:
            text = str(v).strip().lower()
            if text not in controllers():
                problems.append(f"--vary controller: {v!r} is not a controller (expected one "
                                f"of {', '.join(controllers())})")
            else:
                why = _does_not_apply(text, system)
                if why is not None:
                    problems.append(f"--vary controller: {why}")
            values.append(text)
        if low is not None:
            problems.append("--vary controller: expected a list of controllers (lqr,lqg)")
    elif kind == "delay":
        for v in raw:
            text = str(v).strip().lower()
            if text not in ("0", "1", "true", "false", "0.0", "1.0"):
                problems.append(f"--vary delay: {v!r} is not 0 or 1")
                continue
            values.append(text in ("1", "true", "1.0"))
        if low is not None:
            problems.append("--vary delay: expected a list of 0 and 1")
    else:
        values = [_number(v, f"--vary {name}", problems) for v in raw]
        checked = [v for v in values if v is not None]
        if low is not None and high is not None:
            checked += [low, high]
        for v in sorted(set(checked)):
            problem = None
            if kind == "parameter":
                problem = params[name].check(v)
                if problem:
                    problem = f"--vary {name}: {problem}"
            elif kind == "rate" and not v > 0:
                problem = f"--vary rate: {v:g} Hz is not a positive sample rate"
            elif kind in ("q", "r") and not v > 0:
                problem = f"--vary {name}: a Bryson scale must be > 0, got {v:g}"
            elif kind == "noise" and not v >= 0:
                problem = f"--vary noise: a noise scale must be >= 0, got {v:g}"
            if problem:
                problems.append(problem)
                break
    if len(problems) > before:
        return None
    if len(set(values)) != len(values):
        problems.append(f"--vary {name}: a value is given twice")
        return None
    return Axis(name, kind, tuple(values), low, high, log)


def make_study(
    system: str,
    *,
    vary: Mapping[str, object] | Sequence[tuple[str, object]] = (),
    sample: int | None = None,
    runs: int = 100,
    duration: float = 5.0,
    x0: Mapping[str, object] | None = None,
    spread: Mapping[str, object] | None = None,
    settings: Mapping[str, object] | None = None,
    seed: int = 0,
    controller: str = "lqg",
    noise: float | str = 1.0,
    delay: bool = False,
    rate: float | None = None,
    design_for: str = "point",
    metrics: str = "full",
    roa: Mapping[str, object] | None = None,
    batch_size: int | None = None,
) -> Study:
    """A validated :class:`Study`; every problem is collected and raised at once.

    Parameters
    ----------
    system : str
        Catalogue name (``settings`` picks a variant and fixed parameters).
    vary : mapping or pairs name -> values
        Varied quantities (see the module docstring); text as on the
        command line, a list, or a mapping ``{low, high, n, log}``.
    sample : int, optional
        Draw this many random points instead of the full grid.
    runs : int
        Closed-loop runs per point.
    x0 : mapping state -> (low, high) or "LOW:HIGH" or value
        Initial-state ranges (absolute; the other states at the operating point).
    spread : mapping parameter -> relative spread
    controller, noise, delay, rate :
        Values of the quantities that are not varied (``rate`` defaults to
        the rig's control rate; ``noise`` is a scale or ``on``/``off``).
    design_for : ``point`` or ``nominal``
        Design each point's controller for its own parameters, or keep the
        nominal design (robustness of one design to the plant's variation).
    metrics : ``full`` or ``basic``
        ``full`` adds settling times and the quadratic cost (the runs'
        trajectories are kept batch by batch for them).
    roa : mapping state -> "LOW:HIGH:N" or (low, high, n)
        A grid of initial states run per point to estimate the region of
        attraction (``roa_fraction``, the share of the grid caught).
    batch_size : int, optional
        Runs per compiled batch (default: as many as fit in about 32 MB of
        trajectories). Part of the study: the noise seeds follow it.

    Raises
    ------
    StudyError
        Naming every problem.
    """
    from equilibrist.numeric.system import get_system
    from equilibrist.systems import files, registry

    problems: list[str] = []
    # An unknown system or a bad system file is its own clear error.
    if files.looks_like_path(system):
        files.from_file(system)
    else:
        registry.lookup_family(system)
    # Numbers as floats: a study file's 1 and the command line's 1.0 are one study.
    fixed = {k: float(v) if isinstance(v, int | float) and not isinstance(v, bool) else v
             for k, v in (settings or {}).items()}
    sysm = get_system(system, **fixed)
    spec = sysm.spec
    if sysm.n_inputs == 0:
        raise StudyError(f"{sysm.key} has no input: a study needs a controller to design")
    sampled = sample is not None
    n_sample = None
    if sampled:
        n_sample = _whole(sample, "--sample random:N", problems)
    items = list(vary.items()) if isinstance(vary, Mapping) else list(vary)
    names = [n for n, _ in items]
    for n in sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"--vary {n} is given twice")
    axes = []
    for name, value in items:
        if name in fixed:
            problems.append(f"--vary {name}: it is also fixed with --set")
            continue
        ax = _axis(sysm, str(name).strip(), value, sampled, problems)
        if ax is not None:
            axes.append(ax)
    if sampled and not items:
        problems.append("--sample random:N needs at least one --vary range")
    n_runs = _whole(runs, "--runs", problems)
    dur = _number(duration, "--duration", problems)
    if dur is not None and dur <= 0:
        problems.append(f"--duration must be positive, got {dur:g}")
    seed_v = _whole(seed, "--seed", problems, minimum=0)
    if controller not in controllers():
        problems.append(f"--controller {controller!r}: expected one of {', '.join(controllers())}")
    elif _does_not_apply(controller, sysm) is not None:
        problems.append(f"--controller {controller}: {_does_not_apply(controller, sysm)}")
    if isinstance(noise, str):
        noise_v = {"on": 1.0, "off": 0.0}.get(noise.strip().lower())
        if noise_v is None:
            noise_v = _number(noise, "--noise", problems)
    else:
        noise_v = _number(noise, "--noise", problems)
    if noise_v is not None and noise_v < 0:
        problems.append(f"--noise must be >= 0, got {noise_v:g}")
    rate_v = float(spec.control_rate) if rate is None else _number(rate, "--rate", problems)
    if rate_v is not None and rate_v <= 0:
        problems.append(f"--rate must be positive, got {rate_v:g}")
    if design_for not in DESIGN_FOR:
        problems.append(f"--design-for {design_for!r}: expected point or nominal")
    if metrics not in METRICS:
        problems.append(f"--metrics {metrics!r}: expected full or basic")
    x0_r = _ranges(sysm, x0 or {}, "--x0", problems, counted=False)
    roa_r = _ranges(sysm, roa or {}, "--roa", problems, counted=True)
    spread_v: dict[str, float] = {}
    for name, rel in (spread or {}).items():
        if name not in spec.parameter_names:
            problems.append(f"--spread: unknown parameter {name!r} of {sysm.key} "
                            f"({nearest(name, spec.parameter_names)})")
            continue
        v = _number(rel, f"--spread {name}", problems)
        if v is not None and not 0 <= v < 1:
            problems.append(f"--spread {name}: expected a relative spread in [0, 1), got {v:g}")
        elif v is not None:
            spread_v[name] = v
    if dur is not None and rate_v is not None and dur > 0:
        fastest = max([rate_v] + [float(v) for a in axes if a.kind == "rate"
                                  for v in (a.values or (a.high,)) if v is not None])
        if dur * fastest > MAX_RUN_SAMPLES:
            problems.append(f"--duration {dur:g} s at {fastest:g} Hz is {dur * fastest:.3g} samples "
                            f"a run: at most {MAX_RUN_SAMPLES} ({MAX_RUN_SAMPLES / fastest:g} s at "
                            "that rate)")
    if problems:
        raise StudyError("; ".join(problems))
    assert n_runs is not None and dur is not None and seed_v is not None
    assert noise_v is not None and rate_v is not None
    study = Study(
        system=system, settings=fixed, axes=tuple(axes), sample=n_sample, runs=n_runs,
        duration=dur, x0={k: (v[0], v[1]) for k, v in x0_r.items()}, spread=spread_v,
        seed=seed_v, controller=controller,
        noise=noise_v, delay=bool(delay), rate=rate_v, design_for=design_for, metrics=metrics,
        roa={k: (lo, hi, int(n)) for k, (lo, hi, n) in roa_r.items()}, batch_size=1,
    )
    if study.n_points > MAX_POINTS:
        raise StudyError(f"the study has {study.n_points} points: at most {MAX_POINTS} per study "
                         "(split it, or draw a random sample)")
    if batch_size is None:
        rates = [rate_v] + [float(v) for a in axes if a.kind == "rate"
                            for v in (a.values or (a.high,))]
        rows = int(dur * max(rates)) + 2
        width = 2 * sysm.n_states + len(sysm.output_names) + 3 * sysm.n_inputs
        batch_size = max(8, min(1024, BATCH_CELLS // (rows * width)))
    size = _whole(batch_size, "batch_size", problems)
    if problems or size is None:
        raise StudyError("; ".join(problems))
    return _replace_batch(study, min(size, n_runs))


def _replace_batch(study: Study, size: int) -> Study:
    from dataclasses import replace

    return replace(study, batch_size=size)


def _ranges(system: Any, given: Mapping[str, object], option: str, problems: list[str], *,
            counted: bool) -> dict[str, tuple[float, ...]]:
    out: dict[str, tuple[float, ...]] = {}
    form = "LOW:HIGH:N" if counted else "LOW:HIGH"
    for name, value in given.items():
        if name not in system.state_names:
            problems.append(f"{option}: {system.key} has no state {name!r} "
                            f"({nearest(name, system.state_names)})")
            continue
        if isinstance(value, (list, tuple)):
            parts: list[object] = list(value)
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and not counted:
            parts = [value, value]
        else:
            parts = [t.strip() for t in str(value).split(":")]
            if len(parts) == 1 and not counted:
                parts = parts * 2
        if len(parts) != (3 if counted else 2):
            problems.append(f"{option} {name}={value}: expected {form}")
            continue
        before = len(problems)
        lo = _number(parts[0], f"{option} {name} LOW", problems)
        hi = _number(parts[1], f"{option} {name} HIGH", problems)
        n = _whole(parts[2], f"{option} {name} N", problems) if counted else 1
        if len(problems) > before or lo is None or hi is None or n is None:
            continue
        if lo > hi:
            problems.append(f"{option} {name}={value}: reversed range, LOW {lo:g} is above HIGH {hi:g}")
            continue
        out[name] = (lo, hi, n) if counted else (lo, hi)
    if counted and out:
        cells = math.prod(int(v[2]) for v in out.values())
        if cells > MAX_ROA_STATES:
            grid = " x ".join(str(int(v[2])) for v in out.values())
            problems.append(f"{option}: a grid of {grid} = {cells} initial states per point; at "
                            f"most {MAX_ROA_STATES} (each is a run of every point)")
    return out


# -- study files ------------------------------------------------------------------------

_FILE_KEYS = ("system", "set", "vary", "sample", "runs", "duration", "x0", "spread", "seed",
              "controller", "noise", "delay", "rate", "design_for", "metrics", "roa",
              "batch_size")


def load_study_file(path: str | Path, *, system: str | None = None) -> Study:
    """A study from a TOML file (the keys of :func:`make_study`, ``system`` first).

    A study file that names a Python system file never runs it: the user
    names that file as *system* (``equilibrist sweep FILE.py --study
    study.toml``), and its content must be the content of the file the study
    names where that one can still be read. *system* given with a study of a
    catalogue system must be that system.

    Example::

        system = "cartpole"
        runs = 1000
        duration = 5
        seed = 1
        [vary]
        m_p = "0.5:2:16"            # or {low = 0.5, high = 2, n = 16}
        rate = [50, 100, 200, 500]
        controller = ["lqr", "lqg"]
        [x0]
        theta = "-0.3:0.3"          # or [-0.3, 0.3]
        [spread]
        l = 0.05
    """
    import tomllib

    p = Path(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise StudyError(f"no study file {str(p)!r}") from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"study file {p}: not valid TOML ({exc})") from None
    unknown = sorted(set(data) - set(_FILE_KEYS))
    if unknown:
        raise StudyError(f"study file {p}: unknown key(s) {', '.join(unknown)} "
                         f"(expected {', '.join(_FILE_KEYS)})")
    if "system" not in data:
        raise StudyError(f"study file {p}: no system = \"...\"")
    for key in ("set", "vary", "x0", "spread", "roa"):
        if key in data and not isinstance(data[key], Mapping):
            raise StudyError(f"study file {p}: [{key}] must be a table of NAME = VALUE")
    sample = data.get("sample")
    if isinstance(sample, Mapping):
        if set(sample) != {"random"}:
            raise StudyError(f"study file {p}: [sample] takes random = N")
        sample = sample["random"]
    kwargs = {k: v for k, v in data.items() if k not in ("system", "sample")}
    return make_study(_named_system(p, str(data["system"]), system), sample=sample, **kwargs)


def _named_system(study_file: Path, recorded: str, named: str | None) -> str:
    """The system a study file's *recorded* name stands for, given the user's *named* one."""
    from equilibrist.systems import files

    if not files.is_python_path(recorded):
        if named is not None and named != recorded:
            raise StudyError(f"study file {study_file} is a study of {recorded}, not of {named}")
        return recorded
    if named is None:
        raise StudyError(
            f"study file {study_file} names the Python system file {recorded}: a data file never "
            f"runs code; name the system yourself if you trust that file "
            f"(equilibrist sweep {recorded} --study {study_file})"
        )
    there = Path(recorded).expanduser()
    if not there.is_absolute():
        there = study_file.parent / there
    try:
        theirs = there.read_bytes() if there.is_file() else None
        mine = Path(named).expanduser().read_bytes()
    except OSError:
        return named  # a file that cannot be read is refused, in one line, by the study itself
    if theirs is not None and theirs != mine:
        raise StudyError(f"{named} is not the system file the study {study_file} names "
                         f"({recorded}): their contents differ")
    return named
