"""Coverage of the identified parameters: the truth within three standard errors.

Logs are recorded by the project's own closed-loop simulator (LQG designed on
the default parameters, process and sensor noise, a PRBS excitation on the
command) on plants whose parameters are set 25 % away from the defaults the
fit starts from. A coverage test over seeds checks the standard errors, not
one lucky run: with honest standard errors the truth lies within three of
them for 99.7 % of logs.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.ident import Identification, Log, identify
from equilibrist.sim.controllers import LQG
from equilibrist.sim.noise import Noise
from equilibrist.sim.run import simulate
from equilibrist.sim.signals import PRBS
from equilibrist.systems import registry

# Parameters fitted per system: masses and inertias that shape the balancing
# dynamics. A system not listed (a new one) fits its first mass.
FREE = {
    "seesaw": ("m1", "m2"),
    "cartpole": ("m_p", "m_c"),
    "double_cartpole": ("m1", "m2"),
    "wheeled_pendulum": ("m", "I"),
    "reaction_wheel_pendulum": ("m", "I_w"),
    "ball_beam": ("I", "m"),
    "ball_beam_servo": ("g",),
    "cmg_robot": ("m_body",),
}


def _free(system) -> tuple[str, ...]:
    """The listed parameters, or the first mass (else parameter) that moves ``f``."""
    spec = system.spec
    if spec.name in FREE:
        return FREE[spec.name]
    rng = np.random.default_rng(0)
    x = system.operating_point().x + 0.1 * rng.standard_normal(system.n_states)
    u = system.operating_point().u + 0.1 * rng.standard_normal(system.n_inputs)
    base = system.f(x, u)
    candidates = sorted((p for p in spec.parameters if p.default > 0), key=lambda p: p.unit != "kg")
    for p in candidates:
        moved = system.with_params(**{p.name: 1.25 * p.default}).f(x, u)
        if np.max(np.abs(moved - base)) > 1e-6 * (1.0 + np.max(np.abs(base))):
            return (p.name,)
    raise AssertionError(f"no parameter of {spec.key} moves its dynamics")


def _log(plant, nominal, *, seed: int, duration: float, amplitude: float, period: float = 0.2):
    d = design(nominal, rate=nominal.spec.control_rate)
    run = simulate(plant, LQG.from_design(d), duration=duration, noise=Noise.from_design(d),
                   seed=seed, excitation=PRBS(amplitude, period, seed=seed))
    return run, Log.from_arrays(nominal, run.time, run.applied,
                                {o: run.measurement(o) for o in run.output_names})


#: Each experiment fitted once per module: the CMG robot's log of seed 0 (8 s, 0.05 N m) is
#: both its row of the every-system test and the first of its bias test's eight.
_FITS: dict[tuple[object, ...], tuple[bool, Identification | None]] = {}


def _fit(nominal, truth: dict[str, float], *, seed: int, duration: float,
         amplitude: float) -> tuple[bool, Identification | None]:
    """Whether the plant with *truth* fell in the experiment, and if not, the fit of
    *truth*'s parameters to its log (from *nominal*'s values)."""
    key = (nominal.spec.key, tuple(np.asarray(nominal.p, float).tolist()), tuple(truth.items()),
           seed, duration, amplitude)
    if key not in _FITS:
        run, log = _log(nominal.with_params(**truth), nominal, seed=seed, duration=duration,
                        amplitude=amplitude)
        _FITS[key] = (run.fell, None if run.fell else identify(nominal, log, list(truth)))
    return _FITS[key]


def _z(result: Identification, truth: dict[str, float]) -> list[float]:
    return [(result.estimate(n).value - v) / result.estimate(n).std_error for n, v in truth.items()]


@pytest.mark.slow
def test_cartpole_estimates_cover_the_truth_over_seeds():
    nominal = get_system("cartpole")
    truth = {"m_p": 1.3, "b_c": 0.8, "b_p": 0.02}
    # Twelve logs is what the bounds below need: with honest standard errors, z is standard
    # normal, and a parameter fails the coverage (two of 12 beyond 3) with probability
    # 4.7e-4 and the spread (12 rms^2 ~ chi^2_12 outside 12 * 0.4^2 .. 12 * 2^2) with 4.8e-4:
    # 0.3 % for the three, the 99.7 % of three standard errors. Eleven logs would be 0.37 %.
    z = []
    for seed in range(12):
        fell, result = _fit(nominal, truth, seed=seed, duration=15.0, amplitude=20.0)
        assert not fell and result is not None
        z.append(_z(result, truth))
    z = np.array(z)
    covered = np.mean(np.abs(z) < 3.0, axis=0)
    assert np.all(covered >= 0.9), (covered, z)
    # Honest, not merely wide: the spread of the errors is that of the standard errors.
    rms = np.sqrt(np.mean(z**2, axis=0))
    assert np.all(rms > 0.4) and np.all(rms < 2.0), rms


def _pole_check(nominal, result: Identification, truth: dict[str, float]) -> None:
    """The poles designed on the estimates match those on the truth (as the
    coefficients of their polynomial), within what the estimates' covariance
    allows (propagated by finite differences): jointly at the 99.9 % level,
    and each coefficient within four of its standard deviations."""
    names = list(truth)
    est = np.array([result.estimate(n).value for n in names])
    se = np.array([result.estimate(n).std_error for n in names])
    idx = [[e.name for e in result.estimates].index(n) for n in names]
    cov = result.correlation[np.ix_(idx, idx)] * np.outer(se, se)

    def poles(values: np.ndarray) -> np.ndarray:
        # The closed-loop characteristic polynomial's coefficients: smooth in the
        # parameters where the poles themselves are not (a complex pair turning real).
        sysm = nominal.with_params(**dict(zip(names, values.tolist(), strict=True)))
        return np.poly(design(sysm).poles).real[1:]

    p_true = poles(np.array(list(truth.values())))
    p_est = poles(est)
    J = np.column_stack([(poles(est + 1e-4 * se[k] * np.eye(len(names))[k]) - p_est) / (1e-4 * se[k])
                         for k in range(len(names))])
    # Jointly (the coefficients all move with the same few estimates): the
    # mismatch's Mahalanobis distance within the 99.9 % quantile of chi^2.
    cov_p = J @ cov @ J.T
    d = p_est - p_true
    distance = float(d @ np.linalg.pinv(cov_p, rcond=1e-10, hermitian=True) @ d)
    assert distance <= chi2.ppf(0.999, len(names)), (p_est, p_true, distance)
    assert np.all(np.abs(d) <= 4.0 * np.sqrt(np.diag(cov_p)) + 1e-9 * np.abs(p_true)), (p_est, p_true)


ACTUATED = [e.spec.key for e in registry.all_entries() if e.spec.inputs]


@pytest.mark.slow
@pytest.mark.parametrize("key", ACTUATED)
def test_every_actuated_system_recovers_its_parameters(key):
    name = key.partition("[")[0]
    nominal = get_system(name)
    spec = nominal.spec
    free = _free(nominal)
    truth = {n: 1.25 * float(nominal.params[n]) for n in free}
    amplitude = 0.5 * float(spec.design_scales.get(spec.inputs[0].name, 1.0))
    # One log of 8 s a rig (a fit left biased, or at its start, lies as many standard
    # errors from the truth as on either of two such logs): the standard errors'
    # honesty over many logs is the cart-pole's and the CMG robot's tests.
    fell, result = _fit(nominal, truth, seed=0, duration=8.0, amplitude=amplitude)
    if fell:  # too strong for this rig: the experiment is made gentler
        fell, result = _fit(nominal, truth, seed=0, duration=8.0, amplitude=amplitude / 4)
    assert not fell and result is not None
    assert result.method["name"] == "prediction error"
    _pole_check(nominal, result, truth)
    z = np.array(_z(result, truth))
    assert np.all(np.abs(z) < 3.0), z


@pytest.mark.slow
def test_closed_loop_process_noise_does_not_bias_the_estimate():
    """The control-moment-gyroscope robot's flywheels shake the body: large process
    noise that its controller answers. A fit that leaves that noise out of its
    residuals' model (multiple shooting alone) puts ``m_body`` 1.6 standard
    errors high on average over these 8 logs; the errors of an unbiased
    estimate average zero within 3 / sqrt(8) standard errors, and spread as
    the standard errors say."""
    nominal = get_system("cmg_robot")
    truth = {"m_body": 1.25}
    # Eight logs is what the check needs: the mean of n honest z is normal with deviation
    # 1 / sqrt(n), and that of the biased fit's z lies 1.6 higher; with the bound at
    # 3 / sqrt(n), n = 8 finds that bias with probability 0.94 (6 logs: 0.82), and the
    # spread's bounds (n rms^2 ~ chi^2_n) fail honest errors with probability 0.028.
    z = []
    for seed in range(8):
        fell, result = _fit(nominal, truth, seed=seed, duration=8.0, amplitude=0.05)
        assert not fell and result is not None
        z.extend(_z(result, truth))
    z = np.array(z)
    assert abs(z.mean()) < 3.0 / np.sqrt(z.size), z
    assert 0.5 < np.sqrt(np.mean(z**2)) < 1.6, z
