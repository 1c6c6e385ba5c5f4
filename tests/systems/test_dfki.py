"""DFKI's double pendulum (dfki_double_pendulum, both robots) and its identified parameter files.

The derived model is held to a second derivation written here: the rig's own published form
``M(q) q_ddot + C(q, q_dot) q_dot = G(q) + B u - F(q_dot)`` with the rotors' terms in ``M``
(DFKI double_pendulum's "UnderactuatedLecture" plant), typed from the formulas.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.errors import ParameterError
from equilibrist.systems.dfki_parameters import read_model_parameters, settings_of

IDENTIFIED = """I1: 0.031887199591513114
I2: 0.05086984812807257
Ir: 6.287203962819607e-05
b1: 0.001
b2: 0.001
cf1: 0.16
cf2: 0.12
g: 9.81
gr: 6.0
l1: 0.2
l2: 0.3
m1: 0.5234602302310271
m2: 0.6255677234174437
r1: 0.2
r2: 0.25569305436052964
tl1: 10.0
tl2: 10.0
"""


def textbook(p: dict[str, float], x: np.ndarray, u: np.ndarray) -> np.ndarray:
    q1, q2, w1, w2 = x
    m1, m2, l1, r1, r2, I1, I2 = (p[k] for k in ("m1", "m2", "l1", "r1", "r2", "I1", "I2"))
    Ir, gr, g = p["Ir"], p["gr"], p["g"]
    c2, s2 = math.cos(q2), math.sin(q2)
    M = np.array([[I1 + I2 + m2 * l1**2 + 2 * m2 * l1 * r2 * c2 + gr**2 * Ir + Ir,
                   I2 + m2 * l1 * r2 * c2 - gr * Ir],
                  [I2 + m2 * l1 * r2 * c2 - gr * Ir, I2 + gr**2 * Ir]])
    C = np.array([[-2 * m2 * l1 * r2 * s2 * w2, -m2 * l1 * r2 * s2 * w2],
                  [m2 * l1 * r2 * s2 * w1, 0.0]])
    G = np.array([-m1 * g * r1 * math.sin(q1) - m2 * g * (l1 * math.sin(q1) + r2 * math.sin(q1 + q2)),
                  -m2 * g * r2 * math.sin(q1 + q2)])
    F = np.array([p["b1"] * w1 + p["cf1"] * math.atan(100 * w1),
                  p["b2"] * w2 + p["cf2"] * math.atan(100 * w2)])
    qdd = np.linalg.solve(M, -C @ np.array([w1, w2]) + G + u - F)
    return np.array([w1, w2, *qdd])


@pytest.mark.parametrize(("robot", "joint"), [("acrobot", 1), ("pendubot", 0)])
def test_the_derived_rig_is_the_rigs_published_plant(robot: str, joint: int) -> None:
    rng = np.random.default_rng(7)
    # Off the identified values, with a negative damping and an inertia about the joint
    # below m r^2 (no rigid body, as identifications can give): the same equations hold.
    params = {"m1": 0.61, "m2": 0.47, "l1": 0.23, "l2": 0.31, "r1": 0.18, "r2": 0.27,
              "I1": 0.035, "I2": 0.02, "Ir": 8e-5, "gr": 7.0, "b1": -0.01, "b2": 0.02,
              "cf1": 0.1, "cf2": 0.2, "g": 9.7}
    system = get_system("dfki_double_pendulum", robot=robot, **params)
    for _ in range(6):
        x = rng.uniform(-3.0, 3.0, 4)
        tau = float(rng.uniform(-5.0, 5.0))
        u = np.zeros(2)
        u[joint] = tau
        want = textbook(params, x, u)
        np.testing.assert_allclose(system.f(x, np.array([tau])), want, rtol=1e-12,
                                   atol=1e-12 * float(np.max(np.abs(want))))


def test_an_identified_file_binds_as_it_is(tmp_path) -> None:
    path = tmp_path / "model_parameters.yml"
    path.write_text(IDENTIFIED)
    settings = read_model_parameters(path, robot="pendubot")
    assert settings["tau_max"] == 10.0 and settings["tau_min"] == -10.0
    assert settings["Ir"] == 6.287203962819607e-05 and "tl1" not in settings
    assert settings["robot"] == "pendubot"
    system = get_system("dfki_double_pendulum", **settings)
    x = np.array([0.4, -0.3, 1.5, -2.0])
    np.testing.assert_allclose(system.f(x, np.array([1.0])),
                               textbook({k: float(v) for k, v in settings.items() if k != "robot"}, x, np.array([1.0, 0.0])), rtol=1e-12)


@pytest.mark.parametrize(("text", "words"), [
    ("m1: 0.5\nm1: 0.6\n", "m1 is given twice"),
    ("m1: heavy\n", "is not a finite number"),
    ("mass: 0.5\n", "unknown parameter mass"),
    ("- m1\n", "is not 'name: number'"),
    ("tl2: -1\n", "expected a positive number"),
])
def test_a_bad_file_is_refused_in_one_line(tmp_path, text: str, words: str) -> None:
    path = tmp_path / "model_parameters.yml"
    path.write_text(text)
    with pytest.raises(ParameterError, match=words) as caught:
        read_model_parameters(path, robot="acrobot")
    assert "\n" not in str(caught.value)
    with pytest.raises(ParameterError, match="no parameter file"):
        read_model_parameters(tmp_path / "missing.yml", robot="acrobot")


class _RigParameters:
    """The shape of the rig's own parameter object (double_pendulum's model_parameters)."""

    m, l, r, I = [0.5, 0.6], [0.2, 0.3], [0.2, 0.25], [0.03, 0.05]
    b, cf, tl = [0.0, -0.01], [0.0, -0.1], [0.0, 6.0]
    Ir, gr, g = 0.0, 6.0, 9.81


def test_the_rigs_parameter_object_gives_the_same_settings() -> None:
    got = settings_of(_RigParameters(), robot="acrobot")
    assert got["tau_max"] == 6.0 and got["tau_min"] == -6.0 and got["cf2"] == -0.1
    assert get_system("dfki_double_pendulum", **got).params["b2"] == -0.01
    with pytest.raises(ParameterError, match="tl1 = 0 is the pendubot's torque limit"):
        settings_of(_RigParameters(), robot="pendubot")
