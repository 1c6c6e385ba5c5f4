"""One contract, every system of the registry (dm_control's suite style).

Each registered spec (variants included) is checked for what SYSTEMS.md
promises of every system: complete metadata, an operating point that is an
equilibrium, symbolic Jacobians equal to finite differences, and energy
conservation without friction and input along an accurate trajectory.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from tests.support.jacobians import central_differences

from equilibrist.errors import NoEquilibriumError
from equilibrist.mechanics.definition import Entry
from equilibrist.numeric.lookup import get_system
from equilibrist.systems import registry

ENTRIES = registry.all_entries()
IDS = [e.spec.key for e in ENTRIES]



def frictions(entry: Entry) -> tuple[str, ...]:
    """The parameters the definition marks dissipative (``friction(...)``): zeroed for the
    energy test, which fails if one is missing; each alone must take energy out
    (``test_each_friction_dissipates``), which fails if one is marked wrongly."""
    return tuple(p.name for p in entry.spec.parameters if p.dissipative)


# Reduced first-order models have no energy to conserve (SYSTEMS.md: the
# servo model drops the beam's dynamics); listed here, not skipped silently.
NO_ENERGY = {"ball_beam_servo"}
# Reference points for systems without a canonical operating point.
REFERENCE_STATE = {"gyroscope[euler=zxz]": {"theta": 0.8, "psi_dot": 30.0, "phi_dot": 1.0}}
SETTLE = {"gyroscope[euler=zxz]": {}, "gyroscope[euler=xyz]": {}}


def system_for(entry: Entry, **params: float):
    settings_ = {} if entry.spec.variant is None else {entry.spec.variant[0]: entry.spec.variant[1]}
    return get_system(entry.spec.name, **settings_, **params)


def reference_point(system) -> tuple[np.ndarray, np.ndarray]:
    if system.key in REFERENCE_STATE:
        x = np.zeros(system.n_states)
        for k, v in REFERENCE_STATE[system.key].items():
            x[system.state_index(k)] = v
        return x, np.zeros(system.n_inputs)
    eq = system.operating_point()
    return eq.x, eq.u


def test_every_system_module_registers_a_system() -> None:
    # Found in the package, with no list to edit: a module that declares nothing is an error.
    import pkgutil

    import equilibrist.systems as pkg

    modules = {f"{pkg.__name__}.{m.name}" for m in pkgutil.iter_modules(pkg.__path__)
               if not m.name.startswith("_")
               and m.name not in {"registry", "files", "dfki_parameters"}}
    assert {e.module for e in ENTRIES} == modules
    assert len(registry.family_names()) == len({e.spec.name for e in ENTRIES})
    assert set(registry.variants("gyroscope")) == {"zxz", "xyz"}
    assert registry.default_variant("gyroscope") == "zxz"


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_spec_metadata(entry: Entry) -> None:
    spec = entry.spec
    names = spec.parameter_names
    assert len(set(names)) == len(names)
    assert all(n.isidentifier() for n in names)
    for p in spec.all_parameters:
        assert p.check(p.default) is None, p.name
        assert p.unit is not None and p.meaning
    assert "g" in names
    assert set(spec.outputs) <= set(spec.state_names)
    assert set(spec.region) <= set(spec.state_names)
    for s in spec.state_names:
        assert spec.state_unit(s), f"{s} has no unit"
    if spec.inputs:
        assert spec.operating_point is not None
        assert len(spec.outputs) >= len(spec.inputs)
        missing = set(spec.state_names) | set(spec.input_names)
        missing -= set(spec.design_scales)
        assert not missing, f"design scales missing for {missing}"
        assert set(spec.sensor_noise) >= set(spec.outputs)
        for i in spec.inputs:
            assert i.low < i.high


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_operating_point_is_equilibrium(entry: Entry) -> None:
    system = system_for(entry)
    if entry.spec.operating_point is None:
        with pytest.raises(NoEquilibriumError, match="no canonical operating point"):
            system.operating_point()
        return
    eq = system.operating_point()
    assert eq.residual < 1e-9
    xdot = system.f(eq.x, eq.u)
    assert np.allclose(xdot, 0.0, atol=1e-9)
    lm = system.linearize()
    assert lm.residual < 1e-9
    assert lm.C.shape == (len(system.output_names), system.n_states)


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_jacobians_equal_finite_differences(entry: Entry, seed: int) -> None:
    # Non-zero frictions so that their derivatives are exercised too.
    system = system_for(entry)
    lossy = {k: 0.05 for k in frictions(entry)}
    if "eps" in system.params:
        lossy["eps"] = 0.5  # keep tanh smooth on the finite-difference scale
    system = system.with_params(**lossy)
    rng = np.random.default_rng(seed)
    x0, u0 = reference_point(system)
    x = x0 + rng.uniform(-0.4, 0.4, system.n_states)
    u = u0 + rng.uniform(-1.0, 1.0, system.n_inputs)
    A, B = system.jacobians(x, u)
    A_fd, B_fd = central_differences(system, x, u)
    scale = 1.0 + np.abs(A_fd).max()
    assert np.allclose(A, A_fd, rtol=1e-5, atol=1e-6 * scale)
    if system.n_inputs:
        assert np.allclose(B, B_fd, rtol=1e-5, atol=1e-6 * (1.0 + np.abs(B_fd).max()))


def _unforced(system, x_start: np.ndarray, t_end: float, *, rtol: float):
    """The motion from *x_start* with no input (DOP853, tight tolerances), and its energies."""
    u = np.zeros(system.n_inputs)
    fn, p = system.functions.f, system.p
    buf = np.empty(system.n_states)

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        fn(x, u, p, buf)
        return buf.copy()

    sol = solve_ivp(rhs, (0.0, t_end), x_start, method="DOP853", rtol=rtol, atol=1e-12)
    assert sol.success
    return sol, np.array([system.energy(xk) for xk in sol.y.T])


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_energy_conserved_without_friction_and_input(entry: Entry) -> None:
    if entry.spec.name in NO_ENERGY:
        assert math.isnan(system_for(entry).energy(reference_point(system_for(entry))[0]))
        return
    system = system_for(entry, **{k: 0.0 for k in frictions(entry)})
    x0, _ = reference_point(system)
    rng = np.random.default_rng(7)
    x_start = x0 + rng.uniform(-0.3, 0.3, system.n_states)
    sol, energies = _unforced(system, x_start, 1.5, rtol=1e-11)
    # The motion must actually exchange energy between kinds for the test to mean anything.
    moved = np.ptp(sol.y, axis=1).max()
    assert moved > 1e-3
    scale = max(abs(energies[0]), 1e-3 * (1 + np.abs(energies).max()))
    assert np.ptp(energies) / scale < 1e-7, f"energy drifts by {np.ptp(energies):.3g}"


@pytest.mark.parametrize("entry", [e for e in ENTRIES if frictions(e) and e.spec.name not in NO_ENERGY],
                         ids=lambda e: e.spec.key)
def test_each_friction_dissipates(entry: Entry) -> None:
    # Each parameter marked dissipative, alone at a positive value with no input, takes energy
    # out: the energy never rises and ends lower (a parameter marked wrongly, a spring or a
    # mass, fails one of the two).
    rng = np.random.default_rng(11)
    for name in frictions(entry):
        system = system_for(entry, **{k: (0.05 if k == name else 0.0) for k in frictions(entry)})
        x0, _ = reference_point(system)
        x_start = x0 + rng.uniform(-0.3, 0.3, system.n_states)
        x_start[len(x_start) // 2:] += 0.5  # moving, so that every friction acts
        _, energies = _unforced(system, x_start, 1.0, rtol=1e-10)
        scale = 1.0 + np.abs(energies).max()
        assert np.diff(energies).max() < 1e-8 * scale, f"{name}: the energy rises"
        assert energies[-1] < energies[0] - 1e-6 * scale, f"{name}: takes no energy out"
