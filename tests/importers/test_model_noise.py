"""The default noise of an imported model is scaled to the model (issue 26, item 6).

0.05 per sqrt(s) on every rate toppled dm_control's acrobot under its +-2 N*m
motor from upright. The default is now the same on every rate, at most 0.05,
and no more than the default LQR can correct with a fifth of the input's
half range; ``--qn`` sets it (the design's Kalman filter and the simulated
disturbance both follow).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.numeric.lookup import get_system

ROOT = Path(__file__).resolve().parents[2]
ACROBOT = ROOT / "tests" / "models" / "acrobot_named.xml"  # +-2 N m on the elbow
PENDUBOT = ROOT / "examples" / "pendubot.urdf"


def _stayed_up(out: str) -> bool:
    match = re.search(r"stayed_up\s+(True|False)", out)
    assert match, out
    return match.group(1) == "True"


def test_a_weak_motor_gets_less_noise_and_balances_from_upright(capsys) -> None:
    system = get_system(str(ACROBOT))
    noise = system.spec.process_noise
    assert set(noise) == {"shoulder_dot", "elbow_dot"}
    assert len(set(noise.values())) == 1 and 0.005 < noise["elbow_dot"] < 0.02
    assert any("the motors can correct no more" in n for n in system.spec.notes)
    for start in ("shoulder=0", "shoulder=0.002"):
        for seed in ("0", "1"):
            assert main(["simulate", str(ACROBOT), "--x0", start, "--duration", "6",
                         "--seed", seed, "--no-progress"]) == 0
            assert _stayed_up(capsys.readouterr().out), (start, seed)


def test_a_stronger_motor_gets_more_noise_up_to_the_old_default(tmp_path: Path) -> None:
    text = ACROBOT.read_text()
    levels = []
    for gear in ("2", "8", "200"):
        model = tmp_path / f"acrobot_{gear}.xml"
        model.write_text(text.replace('gear="2"', f'gear="{gear}"'))
        levels.append(get_system(str(model)).spec.process_noise["elbow_dot"])
    assert levels[0] < levels[1] < levels[2] == 0.05


def test_the_readme_pendubot_still_balances_from_its_tilt(capsys) -> None:
    # A Kalman filter that assumes too little noise is slow: the scaled default must leave
    # the README's example standing (0.05 rad off upright).
    assert main(["simulate", str(PENDUBOT), "--x0", "shoulder=0.05", "--no-progress"]) == 0
    assert _stayed_up(capsys.readouterr().out)


def test_qn_sets_the_noise_and_the_kalman_filter_follows(capsys) -> None:
    from equilibrist.control.design import design
    from equilibrist.sim.noise import Noise

    system = get_system(str(ACROBOT))
    default = design(system, rate=200.0)
    sigma = system.spec.process_noise["elbow_dot"]
    assert np.diag(default.QN)[2:].tolist() == pytest.approx([sigma**2, sigma**2])
    loud = design(system, rate=200.0, qn=[0.0, 0.0, 0.05**2, 0.05**2])
    assert np.diag(Noise.from_design(loud).process_intensity)[2:].tolist() == pytest.approx(
        [0.05**2, 0.05**2])
    # The filter assumes the larger noise: it trusts the sensors more, and is faster.
    assert not np.allclose(loud.Kf, default.Kf)
    assert np.max(np.abs(loud.estimator_poles)) < np.max(np.abs(default.estimator_poles))
    # On the command line the same option sets what the run draws: the old default topples it.
    assert main(["simulate", str(ACROBOT), "--qn", "0,0,0.0025,0.0025", "--duration", "4",
                 "--no-progress"]) == 0
    assert not _stayed_up(capsys.readouterr().out)


def test_the_rules_solvers_match_scipys() -> None:
    # The rule solves its Riccati and Lyapunov equations with numpy alone (scipy.linalg's
    # import is a tenth of a first run); scipy's Schur-based solvers are the reference.
    from scipy.linalg import solve_continuous_are, solve_continuous_lyapunov

    from equilibrist.importers import _care, _lyapunov
    from equilibrist.importers.tree import read_tree

    rng = np.random.default_rng(3)
    cases = []
    for path in (ACROBOT, ROOT / "tests" / "models" / "leaning_cartpole.xml", ROOT / "examples" / "furuta.xml",
                 ROOT / "tests" / "models" / "cartpole.xml"):
        a, b = (np.array(m, float) for m in read_tree(path).linear)
        assert np.max(np.linalg.eigvals(a).real) > 0.5  # upright: unstable
        cases.append((a, b))
    for n in (2, 4, 6):
        cases.append((rng.normal(size=(n, n)), rng.normal(size=(n, 2))))
    for a, b in cases:
        n, m = a.shape[0], b.shape[1]
        q = np.diag(rng.uniform(0.5, 400.0, n))
        r = np.diag(rng.uniform(0.05, 4.0, m))
        expected = solve_continuous_are(a, b, q, r)
        got = _care(a, b, q, r)
        np.testing.assert_allclose(got, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())
        closed = a - b @ np.linalg.solve(r, b.T @ got)
        w = rng.normal(size=(n, n))
        noise = -(w @ w.T)
        np.testing.assert_allclose(_lyapunov(closed, noise), solve_continuous_lyapunov(closed, noise),
                                   rtol=1e-8, atol=1e-10)
    # No stabilizing solution (an unweighted, uncontrollable integrator): refused, as scipy.
    with pytest.raises(np.linalg.LinAlgError):
        _care(np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)), np.eye(1))
