"""The robustness scorecard drawn: each family's score, each family's successes over its
values, and the model's per-parameter curves (from ``Robustness.describe()``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.viz.plot_common import _figure, _finish, _title

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: The families drawn as curves over their values, with the value's label.
_CURVES = {"velocity_noise": "velocity noise [rad/s]", "torque_noise": "torque noise [N m]",
           "torque_response": "torque response k", "delay": "measurement delay [s]",
           "velocity_noise_filtered": "filtered velocity noise [rad/s]"}


def plot_robustness(card: Mapping[str, Any], path: str | Path | None = None) -> Figure:
    """Draw *card* (``Robustness.describe()``): the scores, the families' success rates over
    their values and the model parameters' curves (a parameter's share of the nominal)."""
    families: Mapping[str, Any] = card["families"]
    fig = _figure(11.0, 7.5)
    grid = fig.add_gridspec(2, 2)
    bars = fig.add_subplot(grid[0, 0])
    names = list(families)
    scores = [families[n]["score"] for n in names]
    bars.barh(range(len(names)), scores, color="tab:blue")
    bars.set_yticks(range(len(names)), [n.replace("_", " ") for n in names])
    bars.invert_yaxis()
    bars.set_xlim(0, 1)
    bars.set_xlabel("score")
    for i, s in enumerate(scores):
        bars.text(min(float(s), 0.88) + 0.01, i, f"{s:.2f}", va="center")
    curves = fig.add_subplot(grid[0, 1])
    for name, label in _CURVES.items():
        if name not in families:
            continue
        fam = families[name]
        values = np.asarray(fam["values"], dtype=float)
        rate = [float(np.mean(s)) for s in fam["successes"]]
        span = values.max() - values.min() if values.size and values.max() > values.min() else 1
        curves.plot((values - values.min()) / span, rate, marker=".", label=label)
    curves.set_xlabel("share of the family's range")
    curves.set_ylabel("success rate")
    curves.set_ylim(-0.05, 1.05)
    if curves.lines:
        curves.legend(fontsize="small")
    model = fig.add_subplot(grid[1, :])
    per = families.get("model", {}).get("parameters", {})
    for k, (pname, succ) in enumerate(per.items()):
        ok = np.asarray(succ, dtype=float)
        xs = np.linspace(0.0, 1.0, len(ok)) if len(ok) else ok
        model.plot(xs, ok + 0.02 * k, marker="o", markersize=3, label=pname)
    model.set_xlabel("share of the parameter's range (0.75 to 1.25 of nominal for a relative "
                     "range; the rig's Ir 0 to 1e-4, b -0.1 to 0.1, cf -0.2 to 0.2)")
    model.set_ylabel("success (1) or not (0)")
    model.set_ylim(-0.1, 1.3)
    if model.lines:
        model.legend(ncol=min(5, len(per)), fontsize="small", loc="upper center")
    _title(fig, f"{card.get('system', '')}: robustness, benchmark score "
                f"{float(card.get('benchmark_score', float('nan'))):.3f}")
    return _finish(fig, path)


__all__ = ["plot_robustness"]
