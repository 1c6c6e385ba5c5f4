"""The tuner: a coordinate search of a controller's settings against its scorecard.

Truths: each candidate's scorecard computed directly (:func:`robustness`, one call per
setting, no search), the search's best their maximum, and each candidate scored once.
"""

from __future__ import annotations

import numpy as np
import pytest

import equilibrist
from equilibrist.errors import SimulationError
from equilibrist.study.robustness import robustness
from equilibrist.study.tune import tune

RUN = {"families": ["delay", "torque_response"], "duration": 1.5, "rate": 200.0, "workers": 1}


def _build(system):
    def build(settings: dict[str, float]) -> object:
        return equilibrist.policy(system, controller="lqr", rate=200.0,
                                  r=[settings["r"]]).controller
    return build


def test_the_tuner_finds_the_best_candidate_each_scored_once() -> None:
    system = equilibrist.get_system("acrobot")
    RUN["x0"] = system.operating_point().x + np.array([0.1, -0.1, 0.0, 0.0])
    values = [300.0, 3.0, 0.01]
    direct = {}
    for r in values:
        card = robustness(system, _build(system)({"r": r}), **RUN)
        direct[r] = float(np.mean([card.scores[f] for f in RUN["families"]]))
    assert len(set(direct.values())) > 1  # the weights matter: a search has something to find
    seen: list[float] = []
    best = tune(system, _build(system), {"r": values}, rounds=3,
                progress=lambda s, v: seen.append(s["r"]), **RUN)
    assert best.score == max(direct.values())
    assert direct[best.settings["r"]] == best.score
    assert sorted(seen) == sorted(values)  # each once, though three rounds were allowed
    assert [s["r"] for s, _ in best.tried] == seen
    assert {s["r"]: v for s, v in best.tried} == direct


def test_the_tuner_refuses_an_empty_or_unknown_space() -> None:
    system = equilibrist.get_system("acrobot")
    with pytest.raises(SimulationError, match="r: no values; start 'q' is not a setting"):
        tune(system, _build(system), {"r": []}, start={"q": 1.0})
    with pytest.raises(SimulationError, match="no settings to tune"):
        tune(system, _build(system), {})
