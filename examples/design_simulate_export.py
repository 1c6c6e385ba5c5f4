"""The whole job on the reaction-wheel pendulum: design, simulate, export, and close the loop in C.

1. Design the digital LQG controller at the rig's control rate.
2. Simulate it on the nonlinear plant with sensor and process noise, a start
   away from upright and a push.
3. Compile the exported C controller and run the same simulation with it in
   the loop: the commands agree with Python's to round-off.

Run: ``.venv/bin/python examples/design_simulate_export.py`` (needs gcc).
"""

from __future__ import annotations

import numpy as np

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.export import c_controller
from equilibrist.sim import LQG, Noise, Pulse, simulate


def main() -> None:
    system = get_system("reaction_wheel_pendulum")
    d = design(system, rate=system.spec.control_rate)
    print(d.summary().splitlines()[0])
    options = {
        "duration": 4.0,
        "x0": {"theta": 0.05},
        "noise": Noise.from_design(d),
        "seed": 1,
        "events": [Pulse(2.0, 0.15, 0.05)],
    }
    python_run = simulate(system, LQG.from_design(d), **options)
    c_run = simulate(system, c_controller(d), **options)
    for label, run in (("Python LQG", python_run), ("exported C", c_run)):
        m = run.metrics()
        applied = float(np.max(np.abs(run.applied)))  # after saturation at the motor's limit
        print(f"{label:11s}: stayed up {m['stayed_up']}, peak applied |tau| {applied:.3f} N*m, "
              f"final theta {m['final_error']['theta']:+.4f} rad")
    gap = float(np.max(np.abs(python_run.applied - c_run.applied)))
    print(f"largest difference between the two controllers' commands: {gap:.3g} N*m")


if __name__ == "__main__":
    main()
