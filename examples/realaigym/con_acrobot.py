"""equilibrist's planned swing-up of the acrobot, as a RealAIGym leaderboard controller.

A controller file of DFKI's double-pendulum benchmark (``double_pendulum``'s v2 leaderboards,
``leaderboard/acrobot/{simulation,robustness}_v2``): it defines ``controller`` (the
benchmark's ``AbstractController``) and ``leaderboard_config``. Copy it into a leaderboard
folder and run the benchmark's own scripts (docs/realaigym.md)::

    python calculate_leaderboard_score.py con_acrobot.py     # simulation_v2
    python benchmark_controller.py con_acrobot.py            # robustness_v2

The controller is built with equilibrist's public API from the folder's own ``mpar`` (its
``sim_parameters.py``: the identified rig, its torque limit), so the same file serves any
identified rig: the rig as a catalogue system (``dfki_double_pendulum``), a swing-up planned on
it by direct collocation (``equilibrist.control.trajopt.plan``), and the time-varying LQR that
tracks the plan and hands over to the balancing LQR (``--controller tvlqr``), stepped as the
compiled controller through ``equilibrist.policy``. A rig whose parameters have friction gets
its motor's joint's friction cancelled (``--friction-compensation on``: the plan and the
tracker are made for the rig that leaves).
"""

import os

import numpy as np
from double_pendulum.controller.abstract_controller import AbstractController
from sim_parameters import mpar

import equilibrist
from equilibrist.control.compensation import compensated_system, compensation
from equilibrist.control.trajopt import plan
from equilibrist.systems.dfki_parameters import settings_of

ROBOT = "acrobot"
#: The plan: its duration [s], collocation intervals, the weight of the rates' squares beside
#: the torque's in its cost (a swing-up that moves no faster than it must), and of the
#: torque's rate squared (a smooth command).
DURATION, KNOTS, RATE_COST, SMOOTHING = 2.5, 100, 0.1, 0.0
#: Compare the angles modulo a turn (a rig pushed over is caught upright again).
WRAP = "on"
#: Hand over to the balancing LQR as soon as the state is in its catch region ("on"), or at
#: the plan's end ("off": the tracker's gains end in the LQR's, no jump of the torque).
CATCH = "on"
#: The rates the controller uses: "differenced" from the measured angles (second-order
#: backward differences, (3 q_k - 4 q_k-1 + q_k-2) / (2 dt), as a rig computes them from
#: its encoders, inside the compiled controller: no noise of the measured rates gets in),
#: or "measured" as the loop hands them.
VELOCITY = "differenced"
#: Cancel the friction of the motor's joint as the rig's model has it (its damping and
#: Coulomb friction, at the rates the controller uses) and plan and design the tracker for
#: the rig it leaves ("on"), or not ("off"). On the boards' frictionless rig the controller
#: is the same either way.
FRICTION = "on"
#: The trackers' LQR cost: the torque's weight (higher, gentler gains) and the states'
#: (``theta1, theta2, theta1_dot, theta2_dot``; None: Bryson's rule on the rig's design
#: scales, 100, 100, 1, 1).
TORQUE_WEIGHT = 40.0
STATE_WEIGHTS = None

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

    def __init__(self, policy, actuated):
        super().__init__()
        self.policy = policy
        self.actuated = actuated

    def init_(self):
        self.policy.reset()

    def reset_(self):
        self.init_()

    def get_control_output_(self, x, t=None):
        u = np.zeros(2)
        u[self.actuated] = self.policy(0.0 if t is None else t, np.asarray(x, dtype=float))[0]
        return u


def build(mpar, robot, duration=DURATION, knots=KNOTS, rate_cost=RATE_COST,
          smoothing=SMOOTHING, wrap=WRAP, catch=CATCH, velocity=VELOCITY,
          torque_weight=TORQUE_WEIGHT, state_weights=STATE_WEIGHTS, friction=FRICTION):
    """The benchmark controller of equilibrist's planned swing-up for the rig *mpar*."""
    system = equilibrist.get_system("dfki_double_pendulum", **settings_of(mpar, robot=robot))
    # With the motor's friction cancelled, the plan need not push through it.
    planned = compensated_system(system, compensation(system)) if friction == "on" else system
    trajectory = plan(planned, start=np.zeros(4), goal=np.array([np.pi, 0.0, 0.0, 0.0]),
                      knots=knots, duration=duration,
                      state_cost={"theta1_dot": rate_cost, "theta2_dot": rate_cost},
                      input_rate_cost={"tau": smoothing})
    rate = system.spec.control_rate
    weights = {} if state_weights is None else {"q": list(state_weights)}
    policy = equilibrist.policy(system, controller="tvlqr", rate=rate, trajectory=trajectory,
                                wrap=wrap, catch=catch, rates=velocity, r=[torque_weight],
                                friction_compensation=friction, **weights)
    return EquilibristController(policy, actuated=1 if robot == "acrobot" else 0)


controller = build(mpar, ROBOT)
controller.init()
