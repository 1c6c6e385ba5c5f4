"""equilibrist's planned swing-up of the pendubot, as a RealAIGym leaderboard controller.

A controller file of DFKI's double-pendulum benchmark (``double_pendulum``'s v2 leaderboards,
``leaderboard/pendubot/{simulation,robustness}_v2``): it defines ``controller`` (the
benchmark's ``AbstractController``) and ``leaderboard_config``. Copy it into a leaderboard
folder and run the benchmark's own scripts (docs/realaigym.md)::

    python calculate_leaderboard_score.py con_pendubot.py     # simulation_v2
    python benchmark_controller.py con_pendubot.py            # robustness_v2

The controller is built with equilibrist's public API from the folder's own ``mpar`` (its
``sim_parameters.py``: the identified rig, its torque limit), so the same file serves any
identified rig: the rig as a catalogue system (``dfki_double_pendulum``), a swing-up planned on
it by direct collocation (``equilibrist.control.trajopt.plan``), and the time-varying LQR that
tracks the plan and hands over to the balancing LQR (``--controller tvlqr``), stepped as the
compiled controller through ``equilibrist.policy``.
"""

import os

import numpy as np
from double_pendulum.controller.abstract_controller import AbstractController
from sim_parameters import mpar

import equilibrist
from equilibrist.control.trajopt import plan
from equilibrist.systems.dfki_parameters import settings_of

ROBOT = "pendubot"
#: The plan: its duration [s], collocation intervals, the weight of the rates' squares beside
#: the torque's in its cost (a swing-up that moves no faster than it must), and of the
#: torque's rate squared (a smooth command).
DURATION, KNOTS, RATE_COST, SMOOTHING = 2.0, 100, 0.1, 0.0
#: Compare the angles modulo a turn (a rig pushed over is caught upright again).
WRAP = "on"
#: The rates the controller uses: "differenced" from the measured angles (second-order
#: backward differences, as a rig computes them from its encoders: no noise of the
#: measured rates gets in), or "measured" as the loop hands them.
VELOCITY = "differenced"
#: The torque's weight in the trackers' LQR cost (the states' by Bryson's rule, the
#: rig's design scales): higher, gentler gains.
TORQUE_WEIGHT = 4.0

# The leaderboard scripts keep a run under data/<the file's name without con_>.
name = os.path.splitext(os.path.basename(__file__))[0][len("con_"):]
leaderboard_config = {
    "csv_path": name + "/sim_swingup.csv",
    "name": name,
    "simple_name": "equilibrist TVLQR",
    "short_description": "Swing-up planned by direct collocation (IPOPT), tracked by a "
    "time-varying LQR handing over to the LQR, compiled by equilibrist.",
    "readme_path": f"readmes/{name}.md",
    "username": "equilibrist",
}


class EquilibristController(AbstractController):
    """An ``equilibrist.policy`` in the benchmark's controller interface."""

    def __init__(self, policy, actuated, velocity=VELOCITY):
        super().__init__()
        self.policy = policy
        self.actuated = actuated
        self.velocity = velocity
        self.previous = []  # the last two measured angle pairs, the newest first

    def init_(self):
        self.policy.reset()
        self.previous = []

    def reset_(self):
        self.init_()

    def get_control_output_(self, x, t=None):
        y = np.array(x, dtype=float)
        if self.velocity == "differenced":
            angles = y[:2].copy()
            if len(self.previous) == 2:
                # (3 q_k - 4 q_k-1 + q_k-2) / (2 dt): exact for a parabola.
                y[2:] = (3 * angles - 4 * self.previous[0] + self.previous[1]) * (
                    self.policy.rate / 2)
            self.previous = [angles, *self.previous[:1]]
        u = np.zeros(2)
        u[self.actuated] = self.policy(0.0 if t is None else t, y)[0]
        return u


def build(mpar, robot, duration=DURATION, knots=KNOTS, rate_cost=RATE_COST,
          smoothing=SMOOTHING, wrap=WRAP, torque_weight=TORQUE_WEIGHT):
    """The benchmark controller of equilibrist's planned swing-up for the rig *mpar*."""
    system = equilibrist.get_system("dfki_double_pendulum", **settings_of(mpar, robot=robot))
    trajectory = plan(system, start=np.zeros(4), goal=np.array([np.pi, 0.0, 0.0, 0.0]),
                      knots=knots, duration=duration,
                      state_cost={"theta1_dot": rate_cost, "theta2_dot": rate_cost},
                      input_rate_cost={"tau": smoothing})
    rate = system.spec.control_rate
    policy = equilibrist.policy(system, controller="tvlqr", rate=rate, trajectory=trajectory,
                                wrap=wrap, r=[torque_weight])
    return EquilibristController(policy, actuated=1 if robot == "acrobot" else 0)


controller = build(mpar, ROBOT)
controller.init()
