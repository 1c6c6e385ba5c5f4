"""design() over the whole catalogue, and its contract with simulation and export."""

from __future__ import annotations

import dataclasses
import functools
import json
import types

import numpy as np
import pytest

from equilibrist.control import Design, design
from equilibrist.errors import DesignError, DimensionError, UnknownNameError
from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System
from equilibrist.systems import registry


def _entries(actuated: bool) -> list[tuple[str, tuple[tuple[str, str], ...]]]:
    out = []
    for entry in registry.all_entries():
        if bool(entry.spec.inputs) == actuated:
            variant = () if entry.spec.variant is None else (entry.spec.variant,)
            out.append((entry.spec.name, variant))
    return out


ACTUATED = _entries(True)
UNACTUATED = _entries(False)


def _id(case: tuple[str, tuple[tuple[str, str], ...]]) -> str:
    return case[0] + "".join(f"[{k}={v}]" for k, v in case[1])


@functools.cache
def _system(name: str, variant: tuple[tuple[str, str], ...] = ()) -> System:
    return get_system(name, **dict(variant))


@pytest.mark.parametrize("case", ACTUATED, ids=_id)
def test_default_continuous_design_stabilizes(case) -> None:
    d = design(_system(*case))
    assert np.all(d.poles.real < 0)
    assert np.all(d.estimator_poles.real < 0)
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(d.plant.A - d.plant.B @ d.K)),
        np.sort_complex(d.poles),
        rtol=1e-8,
        atol=1e-10,
    )
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(d.plant.A - d.Kf @ d.plant.C)),
        np.sort_complex(d.estimator_poles),
        rtol=1e-8,
        atol=1e-10,
    )
    closed = np.linalg.eigvals(d.compensator.A)  # the compensator alone may be unstable
    assert closed.shape == (d.plant.n_states,)


@pytest.mark.parametrize("case", ACTUATED, ids=_id)
@pytest.mark.parametrize("form", ["current", "predictor"])
def test_default_discrete_design_at_200_hz_stabilizes(case, form: str) -> None:
    d = design(_system(*case), rate=200.0, kalman_form=form)
    assert d.dt == pytest.approx(0.005)
    assert np.all(np.abs(d.poles) < 1)
    assert np.all(np.abs(d.estimator_poles) < 1)
    disc = d.discrete
    assert disc is not None
    assert disc.dt == pytest.approx(0.005)
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(disc.A - disc.B @ d.K)),
        np.sort_complex(d.poles),
        rtol=1e-8,
        atol=1e-10,
    )
    L = d.Kf if form == "predictor" else disc.A @ d.Kf
    np.testing.assert_allclose(
        np.sort_complex(np.linalg.eigvals(disc.A - L @ disc.C)),
        np.sort_complex(d.estimator_poles),
        rtol=1e-7,
        atol=1e-9,
    )


@pytest.mark.parametrize("case", UNACTUATED, ids=_id)
def test_system_without_input_is_refused(case) -> None:
    system = _system(*case)
    with pytest.raises(DesignError, match="has no input: there is no controller to design"):
        design(system)


def test_bryson_defaults_from_the_spec() -> None:
    system = _system("cartpole")
    d = design(system)
    spec = system.spec
    np.testing.assert_allclose(
        np.diag(d.Q), [1 / spec.design_scales[s] ** 2 for s in d.state_names]
    )
    assert d.R[0, 0] == pytest.approx(1 / spec.design_scales["F"] ** 2)
    # Per-sample sensor noise sigma: RN = sigma^2 T so that Rd = RN / T = sigma^2.
    t = 1.0 / spec.control_rate
    np.testing.assert_allclose(np.diag(d.RN), [spec.sensor_noise[o] ** 2 * t for o in d.output_names])
    digital = design(system, rate=spec.control_rate)
    np.testing.assert_allclose(np.diag(digital.Rd), [spec.sensor_noise[o] ** 2 for o in d.output_names])
    expected_qn = [spec.process_noise.get(s, 0.0) ** 2 for s in d.state_names]
    np.testing.assert_allclose(np.diag(d.QN), expected_qn)
    np.testing.assert_array_equal(d.G, np.eye(4))
    assert d.notes == ()  # the cart-pole's rate noise excites every mode


def test_process_noise_floor_only_when_needed() -> None:
    base = _system("ball_beam_servo")
    # The beam angle integrates the commanded rate only: noise on R_dot never
    # reaches it, so its mode s = 0 would be unexcited.
    spec = dataclasses.replace(base.spec, process_noise={"R_dot": 0.05})
    d = design(dataclasses.replace(base, spec=spec))
    assert len(d.notes) == 1
    assert "floor" in d.notes[0]
    assert "s = 0 (theta)" in d.notes[0]
    names = d.state_names
    i, j, k = names.index("theta"), names.index("R"), names.index("R_dot")
    assert d.QN[i, i] == pytest.approx((1e-3 * spec.design_scales["theta"]) ** 2)
    assert d.QN[j, j] == 0.0  # R is excited through R_dot: no floor there
    assert d.QN[k, k] == pytest.approx(0.05**2)
    assert np.all(d.estimator_poles.real < 0)
    # With noise on the angle too, nothing is added.
    noisy = dataclasses.replace(base.spec, process_noise={"R_dot": 0.05, "theta": 0.01})
    assert design(dataclasses.replace(base, spec=noisy)).notes == ()


def test_missing_scales_are_named_not_invented() -> None:
    base = _system("cartpole")
    scales = {k: v for k, v in base.spec.design_scales.items() if k not in ("x_dot", "F")}
    system = dataclasses.replace(base, spec=dataclasses.replace(base.spec, design_scales=scales))
    with pytest.raises(DesignError) as err:
        design(system)
    assert "no design scale for x_dot, F" in str(err.value)
    assert "give q and r" in str(err.value)
    d = design(system, q=[1, 1, 1, 1], r=[1])  # explicit weights need no scales
    assert np.all(d.poles.real < 0)
    silent = dataclasses.replace(
        base, spec=dataclasses.replace(base.spec, sensor_noise={"x": 1e-3})
    )
    with pytest.raises(DesignError, match="no sensor noise for output\\(s\\) theta"):
        design(silent)


def test_explicit_weights_and_errors() -> None:
    system = _system("cartpole")
    d = design(system, q=np.diag([1.0, 2.0, 3.0, 4.0]), r=0.5, qn=[0, 0, 1, 1], rn=[1e-4, 1e-4])
    np.testing.assert_array_equal(np.diag(d.Q), [1, 2, 3, 4])
    assert d.R[0, 0] == 0.5
    with pytest.raises(
        DimensionError, match=r"q has 3 values, expected 4 \(one per x, theta, x_dot, theta_dot\)"
    ):
        design(system, q=[1, 1, 1])
    with pytest.raises(DesignError) as err:
        design(system, q=[-1, 1, 1, 1], r=[0])
    assert "q for x is -1: expected >= 0" in str(err.value)
    assert "r for F is 0: expected > 0" in str(err.value)
    for bad in (0, -5, float("nan"), "fast"):
        with pytest.raises(DesignError, match="rate must be a positive number"):
            design(system, rate=bad)
    with pytest.raises(DesignError, match="discretization 'tustin' is unknown"):
        design(system, discretization="tustin")
    with pytest.raises(DesignError, match="kalman form 'smoother' is unknown"):
        design(system, kalman_form="smoother")
    with pytest.raises(UnknownNameError, match="unknown output 'phi'"):
        design(system, outputs=["phi"])
    with pytest.raises(DesignError, match=r"not detectable.*s = 0 \(x\)"):
        design(system, outputs=["theta"])
    with pytest.raises(DesignError, match="G has 2 noise inputs: give qn"):
        design(system, G=np.eye(4)[:, 2:])
    g = design(system, G=np.eye(4)[:, :2] + np.eye(4)[:, 2:], qn=[1e-2, 1e-2])
    assert g.G.shape == (4, 2)


def test_design_contract_for_simulation_and_export() -> None:
    system = _system("cartpole")
    d = design(system, rate=200.0)
    assert isinstance(d, Design)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.K = d.K  # type: ignore[misc]
    assert d.system_key == "cartpole"
    assert isinstance(d.params, types.MappingProxyType)
    assert d.params["m_c"] == system.params["m_c"]
    assert d.plant.dt is None
    assert d.discrete.dt == d.dt == pytest.approx(1 / 200)
    assert d.discretization == "zoh"
    assert d.kalman_form == "current"
    n, m, p = 4, 1, 2
    shapes = {
        "Q": (n, n),
        "R": (m, m),
        "QN": (n, n),
        "RN": (p, p),
        "G": (n, n),
        "K": (m, n),
        "S": (n, n),
        "Kf": (n, p),
        "P": (n, n),
        "Kc": (m, m),
        "Qd": (n, n),
        "Rd": (p, p),
    }
    for name, shape in shapes.items():
        assert getattr(d, name).shape == shape, name
    assert d.poles.shape == (n,)
    assert d.estimator_poles.shape == (n,)
    assert d.tracked == ("x",)
    assert d.kc_note == ""
    np.testing.assert_allclose(d.Rd, d.RN * 200)
    # "current": the gain M with P the a-priori covariance.
    C = d.discrete.C
    np.testing.assert_allclose(d.Kf, d.P @ C.T @ np.linalg.inv(C @ d.P @ C.T + d.Rd), rtol=1e-10)
    continuous = design(system)
    assert continuous.rate is None
    assert continuous.dt is None
    assert continuous.discrete is None
    assert continuous.Qd is None
    assert continuous.Rd is None
    with pytest.raises(DesignError, match="continuous design has no discrete Kalman filter"):
        _ = continuous.kalman_filter


def test_to_dict_is_strict_json_and_summary_is_readable() -> None:
    d = design(_system("cartpole"), rate=100.0, kalman_form="predictor")
    data = d.to_dict()
    text = json.dumps(data, allow_nan=False)
    back = json.loads(text)
    for key in (
        "K",
        "S",
        "poles",
        "Kf",
        "P",
        "Kc",
        "kc_note",
        "Qd",
        "Rd",
        "estimator_poles",
        "tracked",
        "margins",
        "lqr_margins",
        "controllability",
        "observability",
    ):
        assert key in back, key
    np.testing.assert_allclose(back["K"], d.K)
    assert back["poles"][0].keys() == {"re", "im"}
    np.testing.assert_allclose([complex(p["re"], p["im"]) for p in back["poles"]], d.poles)
    assert back["kalman_form"] == "predictor"
    summary = d.summary()
    assert "LQG design for cartpole: discrete at 100 Hz" in summary
    assert "Kalman gain L (predictor form)" in summary
    assert "reference gain Kc" in summary
