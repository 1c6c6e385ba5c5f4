"""A study's record: the kinds and limits it takes, its error, its axes (:class:`Axis`) and
:class:`Study` itself with its points, seeds and JSON form; used by :mod:`equilibrist.study.spec`.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import EquilibristError

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

FORMAT = "equilibrist-study-1"
#: A value of an axis: a number, a controller kind (text) or a delay (bool).
AxisValue = float | str | bool


def _does_not_apply(kind: str, system: System) -> str | None:
    from equilibrist.controllers import kinds

    return kinds.get(kind).applies(system)


def kind_options(kind: str, options: Mapping[str, str]) -> dict[str, object]:
    """The options of *options* that the kind *kind* takes, parsed (its request's options)."""
    from equilibrist.controllers import kinds

    return {o.key: o.value(options[o.key]) for o in kinds.get(kind).options if o.key in options}


def controllers() -> tuple[str, ...]:
    """The controller kinds a study takes (:mod:`equilibrist.controllers.kinds`, surface ``study``)."""
    from equilibrist.controllers import kinds

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
    """One varied quantity, named as written (``m_p``, ``q.theta``...), of *kind*
    ``parameter``, ``rate``, ``q``, ``r``, ``controller``, ``noise`` or ``delay``: the grid's
    *values* (a random sample's list to draw from), or for a random sample's range *low* and
    *high* (*log*: geometric spacing or log-uniform draws)."""

    name: str
    kind: str
    values: tuple[AxisValue, ...]
    low: float | None = None
    high: float | None = None
    log: bool = False

    @property
    def target(self) -> str:
        """The state, input or parameter the axis acts on (its name for the others)."""
        return self.name.split(".", 1)[1] if self.kind in ("q", "r") else self.name

    def to_dict(self) -> dict[str, object]:
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
    settings: Mapping[str, object]
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
    #: The controllers' own options by key (``trajectory``, ``balance``, ``horizon``...) as
    #: text: each point's kind takes those that are its own.
    controller_options: Mapping[str, str] = field(default_factory=dict)

    # -- points -----------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        if self.sample is not None:
            return self.sample
        return math.prod(len(a.values) for a in self.axes) if self.axes else 1

    @property
    def total_runs(self) -> int:
        return self.n_points * self.runs

    def point(self, index: int) -> dict[str, AxisValue]:
        """The varied quantities' values at point *index* (in axis order)."""
        if not 0 <= index < self.n_points:
            raise StudyError(f"point {index} out of range 0..{self.n_points - 1}")
        if self.sample is None:
            shape = [len(a.values) for a in self.axes]
            idx = np.unravel_index(index, shape) if shape else ()
            return {a.name: a.values[int(i)] for a, i in zip(self.axes, idx, strict=True)}
        gen = np.random.default_rng(self.point_seed(index, 0))
        out: dict[str, AxisValue] = {}
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
    def to_dict(self) -> dict[str, object]:
        # The controllers' options only when given: a study without them keeps its digest.
        extra = ({"controller_options": dict(self.controller_options)}
                 if self.controller_options else {})
        return {
            **extra,
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
        controller_options={str(k): str(v) for k, v in d.get("controller_options", {}).items()},
    )
