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

Before it returns, the file checks its design on its own model of the rig: the swing-up from
hanging at rest, simulated for the boards' 10 s with the rig's own parameters (equilibrist's
compiled simulation, some 10 ms). If that run does not end upright (within the robustness
board's tolerance), it backs off along a short fixed list of settings (``BACK_OFF``: hand over
at the plan's end, then stiffer tracking) and keeps the first that does; on the boards' rig the
first, the file's own settings, does.
"""

import os

import numpy as np
from double_pendulum.controller.abstract_controller import AbstractController
from sim_parameters import mpar

import equilibrist
from equilibrist.control.compensation import compensated_system, compensation
from equilibrist.control.trajopt import plan
from equilibrist.sim import simulate
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
#: What the file tries, in turn, when its design does not balance its own rig in its own
#: simulation: changes of the settings above. First the file's own; then the hand-over at the
#: plan's end (the catch region is where the LQR's command stays within the torque limit,
#: computed on the linearization: on a rig whose nonlinear swing it misjudges, or whose passive
#: joint's friction holds the LQR off upright, the LQR caught early loses the rig or settles off
#: upright, while the tracker brings it to the plan's end, at rest upright); then stiffer tracking.
BACK_OFF = ({}, {"catch": "off"}, {"torque_weight": 10.0}, {"torque_weight": 10.0, "catch": "off"})
#: Check the design on the rig's own model before returning ("on"), or return it unchecked.
CHECK = "on"
#: Upright, as the robustness board judges a run's final state: within these of
#: ``(pi, 0, 0, 0)``, the angles modulo a turn.
TOLERANCE = (0.35, 0.35, 1.0, 1.0)

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
          torque_weight=TORQUE_WEIGHT, state_weights=STATE_WEIGHTS, friction=FRICTION,
          check=CHECK, back_off=BACK_OFF):
    """The benchmark controller of equilibrist's planned swing-up for the rig *mpar*: the
    first of *back_off*'s changes of the settings whose design balances the rig's own model
    (all of them the file's own when *check* is "off" or none does)."""
    system = equilibrist.get_system("dfki_double_pendulum", **settings_of(mpar, robot=robot))
    # With the motor's friction cancelled, the plan need not push through it.
    planned = compensated_system(system, compensation(system)) if friction == "on" else system
    settings = {"duration": duration, "knots": knots, "rate_cost": rate_cost,
                "smoothing": smoothing, "wrap": wrap, "catch": catch, "velocity": velocity,
                "torque_weight": torque_weight, "state_weights": state_weights}
    plans = {}
    first, kept = None, None
    for change in back_off if check == "on" else ({},):
        tried = {**settings, **change}
        key = tuple(tried[k] for k in ("duration", "knots", "rate_cost", "smoothing"))
        if key not in plans:
            plans[key] = plan(planned, start=np.zeros(4),
                              goal=np.array([np.pi, 0.0, 0.0, 0.0]), knots=tried["knots"],
                              duration=tried["duration"],
                              state_cost={"theta1_dot": tried["rate_cost"],
                                          "theta2_dot": tried["rate_cost"]},
                              input_rate_cost={"tau": tried["smoothing"]})
        policy = _policy(system, plans[key], tried, friction)
        if first is None:
            first = policy
        if check != "on" or balances(system, policy):
            kept = change
            break
    else:
        policy = first  # none balances its own rig: the file's own settings
    controller = EquilibristController(policy, actuated=1 if robot == "acrobot" else 0)
    # What the check kept ({}: the file's own settings; None: none balanced, the file's own).
    controller.back_off = kept
    return controller


def _policy(system, trajectory, settings, friction):
    weights = {} if settings["state_weights"] is None else {"q": list(settings["state_weights"])}
    return equilibrist.policy(system, controller="tvlqr", rate=system.spec.control_rate,
                              trajectory=trajectory, wrap=settings["wrap"],
                              catch=settings["catch"], rates=settings["velocity"],
                              r=[settings["torque_weight"]], friction_compensation=friction,
                              **weights)


def balances(system, policy, duration=10.0):
    """Whether *policy*'s controller swings *system* up from hanging at rest and holds it: the
    final state of a *duration* s run within :data:`TOLERANCE` of upright."""
    run = simulate(system, policy.controller, duration=duration, x0=np.zeros(4), region={})
    miss = np.asarray(run.final_state, dtype=float) - np.array([np.pi, 0.0, 0.0, 0.0])
    miss[:2] = (miss[:2] + np.pi) % (2 * np.pi) - np.pi
    return bool(np.all(np.abs(miss) < TOLERANCE))


controller = build(mpar, ROBOT)
controller.init()
