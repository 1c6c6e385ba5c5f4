"""Angular velocity from Euler angles: quaternion derivation vs scipy and the seed.

Independent truths: scipy.spatial.transform.Rotation (rotation matrices,
differentiated by central finite differences: ``omega_hat = R^T R_dot`` in
the body frame, ``R_dot R^T`` in space) and the formulas printed in seed 002
("Angular velocity and quaternion"), typed in from the seed.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from equilibrist.errors import DimensionError, UnknownNameError
from equilibrist.mechanics import rotations

# scipy's intrinsic (upper-case) sequences are the products of SYSTEMS.md.
SCIPY = {"xyz": "XYZ", "zxz": "ZXZ"}

angle = st.floats(-3.0, 3.0, allow_nan=False)
rate = st.floats(-5.0, 5.0, allow_nan=False)


def _vee(S: np.ndarray) -> np.ndarray:
    return np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2


def _finite_difference_omega(sequence: str, angles, rates, frame: str) -> np.ndarray:
    angles, rates = np.asarray(angles), np.asarray(rates)
    h = 1e-6

    def R(t: float) -> np.ndarray:
        return Rotation.from_euler(SCIPY[sequence], angles + t * rates).as_matrix()

    R0 = R(0.0)
    R_dot = (R(h) - R(-h)) / (2 * h)
    return _vee(R0.T @ R_dot if frame == "body" else R_dot @ R0.T)


@pytest.mark.parametrize("sequence", rotations.SEQUENCES)
@pytest.mark.parametrize("frame", rotations.FRAMES)
@settings(max_examples=40, deadline=None)
@given(a=st.tuples(angle, angle, angle), r=st.tuples(rate, rate, rate))
def test_angular_velocity_matches_scipy_finite_differences(sequence, frame, a, r) -> None:
    omega = rotations.angular_velocity(sequence, a, r, frame=frame)
    expected = _finite_difference_omega(sequence, a, r, frame)
    assert np.allclose(omega, expected, atol=1e-7 * (1 + np.abs(r).max()))


@pytest.mark.parametrize("sequence", rotations.SEQUENCES)
def test_rotation_matrix_matches_scipy(sequence) -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.uniform(-3, 3, 3)
        expected = Rotation.from_euler(SCIPY[sequence], a).as_matrix()
        assert np.allclose(rotations.rotation_matrix(sequence, a), expected, atol=1e-14)


@pytest.mark.parametrize("sequence", rotations.SEQUENCES)
def test_space_and_body_frames_differ_by_the_rotation(sequence) -> None:
    rng = np.random.default_rng(5)
    a, r = rng.uniform(-2, 2, 3), rng.uniform(-2, 2, 3)
    body = rotations.angular_velocity(sequence, a, r, frame="body")
    space = rotations.angular_velocity(sequence, a, r, frame="space")
    R = Rotation.from_euler(SCIPY[sequence], a).as_matrix()
    assert np.allclose(space, R @ body, atol=1e-12)


def test_batches_broadcast() -> None:
    rng = np.random.default_rng(11)
    a, r = rng.uniform(-2, 2, (4, 5, 3)), rng.uniform(-2, 2, (4, 5, 3))
    batch = rotations.angular_velocity("zxz", a, r, frame="space")
    assert batch.shape == (4, 5, 3)
    single = rotations.angular_velocity("zxz", a[2, 3], r[2, 3], frame="space")
    assert np.allclose(batch[2, 3], single)


# -- the seed's printed results --------------------------------------------------
def _seed_formulas():
    th, ph, ps = sp.symbols("theta phi psi", real=True)
    thd, phd, psd = sp.symbols("theta_dot phi_dot psi_dot", real=True)
    sin, cos = sp.sin, sp.cos
    return {
        ("xyz", "body"): sp.Matrix([
            thd * cos(ph) * cos(ps) + phd * sin(ps),
            -thd * cos(ph) * sin(ps) + phd * cos(ps),
            thd * sin(ph) + psd,
        ]),
        ("zxz", "body"): sp.Matrix([
            phd * sin(th) * sin(ps) + thd * cos(ps),
            phd * sin(th) * cos(ps) - thd * sin(ps),
            phd * cos(th) + psd,
        ]),
        ("xyz", "space"): sp.Matrix([
            thd + psd * sin(ph),
            phd * cos(th) - psd * cos(ph) * sin(th),
            phd * sin(th) + psd * cos(ph) * cos(th),
        ]),
    }


@pytest.mark.parametrize(("sequence", "frame"), list(_seed_formulas()))
def test_symbolic_angular_velocity_equals_the_seed(sequence, frame) -> None:
    derived = rotations.angular_velocity_expr(sequence, frame=frame)
    seed = _seed_formulas()[(sequence, frame)]
    assert sp.simplify(derived - seed) == sp.zeros(3, 1)


def test_seed_magnitude_of_xyz_angular_velocity() -> None:
    ph = sp.Symbol("phi", real=True)
    thd, phd, psd = sp.symbols("theta_dot phi_dot psi_dot", real=True)
    omega = rotations.angular_velocity_expr("xyz", frame="space")
    seed = thd**2 + psd**2 + phd**2 + 2 * thd * psd * sp.sin(ph)
    assert sp.simplify((omega.T * omega)[0] - seed) == 0


def test_seed_xyz_quaternion_has_half_angles() -> None:
    # The seed prints the components of Rx(theta) Ry(phi) Rz(psi) with full
    # angles; with half angles (what is meant) they are right.
    th, ph, ps = sp.symbols("theta phi psi", real=True)
    q = rotations.euler_quaternion("xyz", (th, ph, ps))
    c1, c2, c3 = sp.cos(th / 2), sp.cos(ph / 2), sp.cos(ps / 2)
    s1, s2, s3 = sp.sin(th / 2), sp.sin(ph / 2), sp.sin(ps / 2)
    seed = [
        c1 * c2 * c3 - s1 * s2 * s3,
        c1 * s2 * s3 + s1 * c2 * c3,
        c1 * s2 * c3 - s1 * c2 * s3,
        c1 * c2 * s3 + s1 * s2 * c3,
    ]
    assert [sp.expand(x - y) for x, y in zip((q.a, q.b, q.c, q.d), seed, strict=True)] == [0] * 4


def test_seed_gravity_direction_in_body_xyz() -> None:
    # Seed: v = q* (0, 0, 0, -1) q = cos(theta) (0, sin(phi) cos(psi),
    # -sin(phi) sin(psi), -cos(phi)) + sin(theta) (0, -sin(psi), -cos(psi), 0).
    rng = np.random.default_rng(2)
    for _ in range(10):
        th, ph, ps = rng.uniform(-3, 3, 3)
        R = rotations.rotation_matrix("xyz", (th, ph, ps))
        v = R.T @ np.array([0.0, 0.0, -1.0])
        seed = np.cos(th) * np.array([np.sin(ph) * np.cos(ps), -np.sin(ph) * np.sin(ps), -np.cos(ph)])
        seed += np.sin(th) * np.array([-np.sin(ps), -np.cos(ps), 0.0])
        assert np.allclose(v, seed, atol=1e-14)


def test_unknown_names_and_bad_shapes_raise() -> None:
    with pytest.raises(UnknownNameError, match="zyx"):
        rotations.angular_velocity("zyx", [0, 0, 0], [0, 0, 0])
    with pytest.raises(UnknownNameError, match="frame"):
        rotations.angular_velocity("xyz", [0, 0, 0], [0, 0, 0], frame="world")
    with pytest.raises(DimensionError, match="3 values"):
        rotations.angular_velocity("xyz", [0, 0], [0, 0, 0])
