"""What the tour's steps share: the default scenario (a rig's definition states its own),
the gyroscope's demo settings, the outcome of one system, and formatting helpers."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import Scenario
from equilibrist.viz.report import Section

if TYPE_CHECKING:
    from equilibrist.numeric.system import System
    from equilibrist.sim.controllers import StateFeedback

#: Seed of the noise of every demo run (the report is reproducible).
SEED = 2024


#: The gyroscope's demo: nutation angle, spin and duration.
GYRO_THETA = 0.6
GYRO_SPIN = 250.0
GYRO_DURATION = 2.0


def default_scenario(system: System, controller: StateFeedback | None = None) -> Scenario:
    """A scenario from the spec alone: start at half a design scale off the operating point
    on the first angle, a push on the first input for 0.1 s.

    The push is half of what the design holds: with *controller* (the design's state
    feedback), the largest impulse it recovers from rest in the real loop
    (:func:`equilibrist.sim.roa.max_push`, noise off) halved, and never more than half the
    input's limit; without one, half the input's limit."""
    scales = dict(system.spec.design_scales)
    coords = [n for n in system.state_names if not n.endswith("_dot")]
    first = next((c for c in coords if c.startswith("theta")), coords[0])
    start = {first: 0.5 * scales.get(first, 0.1)}
    if not system.n_inputs:
        return Scenario(start=start, push=0.0, push_name="")
    low, high = system.input_limits
    limit = float(max(abs(low[0]), abs(high[0])))
    duration = 0.1
    push = 0.5 * limit if math.isfinite(limit) else 1.0
    why = "half the input's limit"
    if controller is not None:
        from equilibrist.sim.roa import max_push

        eq = system.operating_point()
        # The impulse searched up to twice the half-limit push's (0.1 s of it).
        neg, pos, _, _ = max_push(system, controller, 2.0 * push * duration, x_op=eq.x,
                                  u_op=eq.u, duration=3.0)
        held = 0.5 * min(neg, pos) / duration
        if held < push:
            push, why = held, "half of what the design holds"
    unit = system.input_units[0]
    return Scenario(start=start, push=push, push_duration=duration,
                    push_name=f"a push of {push:.3g} {unit} for {duration:g} s ({why})")


@dataclass(frozen=True)
class Outcome:
    """What the tour found for one system: a row of the summary table and a report section.

    ``seconds`` is the wall time the system's tour took (designs, runs, plots and
    animation); ``simulated`` the simulated length of its main run [s]."""

    key: str
    row: tuple[str, ...]
    section: Section
    stayed_up: bool
    seconds: float
    simulated: float = math.nan

    def progress_line(self) -> str:
        """The line the demo prints when the system is done: the outcome of its run over
        the simulated time, and the wall time its tour took, each named."""
        span = f"the {self.simulated:g} s simulated" if math.isfinite(self.simulated) \
            else "its simulated run"
        outcome = f"stayed up for {span}" if self.stayed_up else f"FELL within {span}"
        return f"{self.key}: {outcome} (its tour took {self.seconds:.1f} s of wall time)"


SUMMARY_HEADER = ("system", "controller", "settling after push", "peak input", "final error",
                  "stayed up")


# -- formatting ----------------------------------------------------------------


def _fmt(value: float, unit: str, *, degrees: bool = True, digits: int = 3) -> str:
    from equilibrist.viz.plot_common import display_unit

    f, shown = display_unit(unit, degrees=degrees)
    return f"{f * value:.{digits}g} {shown}".strip()


def _slug(key: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in key).strip("_")


def _say(log: Callable[[str], None] | None, text: str) -> None:
    if log is not None:
        log(text)


def _label(system: System) -> str:
    """How the report names a system: its key, or a user's file by its own name."""
    key = str(system.key)
    if key == system.spec.key:
        return key
    file = Path(key).name
    # A model file's system is named after the file: say it once.
    return file if system.name in (file, Path(key).stem) else f"{system.name} ({file})"
