"""Drake's acrobot swing-up (the Underactuated Robotics notebook), one solve per line of stdin.

Runs under Drake's own environment (bench/peers_drake.sh). Each input line is a seed, or
"straight" for the notebook's straight-line guess; each output line is JSON with
``converged``, ``cpu`` (process CPU seconds of ``Solve``) and ``solver``.
"""

import json
import math
import sys
import time

import numpy as np
from pydrake.all import DirectCollocation, PiecewisePolynomial, Solve
from pydrake.examples import AcrobotPlant


def solve(seed):
    plant = AcrobotPlant()
    context = plant.CreateDefaultContext()
    # The notebook: 21 knots, steps of 0.05 to 0.2 s, |tau| <= 8, cost 10 u^2 + the duration.
    dircol = DirectCollocation(plant, context, num_time_samples=21, minimum_time_step=0.05,
                               maximum_time_step=0.2)
    prog = dircol.prog()
    dircol.AddEqualTimeIntervalsConstraints()
    u = dircol.input()
    dircol.AddConstraintToAllKnotPoints(u[0] >= -8.0)
    dircol.AddConstraintToAllKnotPoints(u[0] <= 8.0)
    x0, xf = (0.0, 0.0, 0.0, 0.0), (math.pi, 0.0, 0.0, 0.0)
    prog.AddBoundingBoxConstraint(x0, x0, dircol.initial_state())
    prog.AddBoundingBoxConstraint(xf, xf, dircol.final_state())
    dircol.AddRunningCost(10 * u[0] ** 2)
    dircol.AddFinalCost(dircol.time())
    if seed is None:
        guess = PiecewisePolynomial.FirstOrderHold([0.0, 4.0], np.column_stack((x0, xf)))
    else:  # random states at the knots: angles in [-pi, pi], rates in [-5, 5] rad/s
        rng = np.random.default_rng(seed)
        xs = np.vstack([rng.uniform(-np.pi, np.pi, (2, 21)), rng.uniform(-5.0, 5.0, (2, 21))])
        guess = PiecewisePolynomial.FirstOrderHold(np.linspace(0.0, 4.0, 21), xs)
    dircol.SetInitialTrajectory(PiecewisePolynomial(), guess)
    t0 = time.process_time()
    result = Solve(prog)
    return {"converged": bool(result.is_success()), "cpu": time.process_time() - t0,
            "solver": result.get_solver_id().name()}


for line in sys.stdin:
    word = line.strip()
    print(json.dumps(solve(None if word == "straight" else int(word))), flush=True)
