"""Tune a controller's settings against its robustness scorecard.

A controller's weights and plan settings (a torque weight, the angles' and rates' weights,
a plan's duration...) are searched for the best benchmark score of
:func:`~equilibrist.study.robustness.robustness`, the families run on the compiled batch
(seconds a candidate). The search is a coordinate search over a few settings, each over a
short list of values: from a start, each setting in turn is tried at every one of its values
with the others held, the best kept; rounds repeat until a round improves nothing (or
``rounds`` is reached). Every candidate is scored once (a cache keyed by its settings), with
the same seed, so two candidates meet the same noise. A grid of a few values a setting is
what the scorecard's resolution warrants: a family's score moves in steps of one run in 21.

    from equilibrist.study.tune import tune

    def build(settings):
        return equilibrist.policy(rig, controller="tvlqr", trajectory=plan, wrap="on",
                                  r=[settings["r"]], q=[settings["q"]] * 2 + [1, 1]).controller

    best = tune(rig, build, {"r": [4, 8, 16], "q": [25, 50, 100]}, start={"r": 4, "q": 100},
                x0=[0, 0, 0, 0])
    best.settings, best.score

The scorecard already spreads its runs over every core, so candidates are scored one
after another.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from equilibrist.errors import SimulationError
from equilibrist.numeric.system import System
from equilibrist.study.robustness import BENCHMARK_FAMILIES, FAMILIES, Robustness, robustness


@dataclass(frozen=True)
class Tuned:
    """The best settings found, their score and scorecard, and every candidate's score in
    the order scored."""

    settings: dict[str, float]
    score: float
    card: Robustness
    tried: list[tuple[dict[str, float], float]]

    def describe(self) -> dict[str, object]:
        return {"settings": self.settings, "score": self.score,
                "scores": self.card.scores,
                "tried": [{"settings": s, "score": v} for s, v in self.tried]}


def tune(system: System, build: Callable[[dict[str, float]], object],
         space: Mapping[str, Sequence[float]], *, start: Mapping[str, float] | None = None,
         rounds: int = 3, families: Sequence[str] = BENCHMARK_FAMILIES,
         progress: Callable[[dict[str, float], float], None] | None = None,
         **scorecard: object) -> Tuned:
    """The settings of *space* whose controller scores best on the robustness scorecard.

    Parameters
    ----------
    system : System
        The plant the scorecard runs (its nominal parameters; the model family varies them).
    build : callable
        ``build(settings)`` -> the controller for a mapping of every setting of *space*.
    space : mapping
        Each setting's values to try (at least one each).
    start : mapping, optional
        Where the search starts (default each setting's first value).
    rounds : int
        The most rounds of the coordinate search.
    families : sequence of str
        The scorecard's families (default the benchmark's six); the score is their mean.
    progress : callable, optional
        ``progress(settings, score)`` after each new candidate.
    **scorecard
        The rest of :func:`~equilibrist.study.robustness.robustness`'s options (``x0``,
        ``rate``, ``duration``, ``seed``, ``workers``...).
    """
    problems = [f"{name}: no values" for name, values in space.items() if len(values) == 0]
    problems += [f"families {f!r} unknown" for f in families if f not in FAMILIES]
    if not space:
        problems.append("no settings to tune")
    begin = {name: float(values[0]) for name, values in space.items() if len(values)}
    for name, value in (start or {}).items():
        if name not in space:
            problems.append(f"start {name!r} is not a setting of the space")
        else:
            begin[name] = float(value)
    if not isinstance(rounds, int) or isinstance(rounds, bool) or rounds < 1:
        problems.append(f"rounds = {rounds!r}: expected a whole number >= 1")
    if problems:
        raise SimulationError("tune: " + "; ".join(problems))
    cards: dict[tuple[float, ...], Robustness] = {}
    tried: list[tuple[dict[str, float], float]] = []
    names = list(space)

    def score(settings: dict[str, float]) -> float:
        key = tuple(settings[n] for n in names)
        if key not in cards:
            card = robustness(system, build(dict(settings)), families=families,
                              **scorecard)  # type: ignore[arg-type]
            cards[key] = card
            value = float(sum(card.scores[f] for f in families) / len(families))
            tried.append((dict(settings), value))
            if progress is not None:
                progress(dict(settings), value)
        return next(v for s, v in tried if tuple(s[n] for n in names) == key)

    best, best_score = dict(begin), score(begin)
    for _ in range(rounds):
        improved = False
        for name in names:
            for value in space[name]:
                candidate = {**best, name: float(value)}
                s = score(candidate)
                if s > best_score:
                    best, best_score, improved = candidate, s, True
        if not improved:
            break
    return Tuned(best, best_score, cards[tuple(best[n] for n in names)], tried)


__all__ = ["Tuned", "tune"]
