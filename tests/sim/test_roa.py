"""``equilibrist roa``: the region of attraction estimated from the real loop."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import Pulse, simulate
from equilibrist.sim.roa import estimate_slice, max_push, max_tilt


@pytest.fixture(scope="module")
def cart_lqr():
    system = get_system("cartpole")
    ctrl = LinearController.from_design(design(system, rate=200.0), kind="lqr")
    eq = system.operating_point()
    return system, ctrl, np.asarray(eq.x, float), np.asarray(eq.u, float)


def test_the_largest_push_is_what_a_real_short_push_shows(cart_lqr) -> None:
    """A second route: the impulse modelled as a start x_op + B J against a 2 ms force pulse of
    J / 2 ms applied by simulate's events, just inside and just outside the threshold."""
    system, ctrl, x_op, u_op = cart_lqr
    neg, pos, _, _ = max_push(system, ctrl, 100.0, x_op=x_op, u_op=u_op, duration=3.0)
    assert 5.0 < pos < 100.0 and neg == pytest.approx(pos, rel=0.02)  # the cart-pole is symmetric
    for factor, caught in ((0.9, True), (1.15, False)):
        j = factor * pos
        run = simulate(system, ctrl, duration=3.0, x0=x_op, noise=None,
                       events=[Pulse(0.0, j / 0.002, 0.002)], physics_step=5e-4)
        ended = bool(not run.fell and abs(run.final_state[1]) < 0.1 and abs(run.final_state[3]) < 0.5)
        assert ended is caught, (factor, run.fell)


def test_the_slice_agrees_with_the_tilt_and_refines_along_its_boundary(cart_lqr) -> None:
    system, ctrl, x_op, _ = cart_lqr
    down, up, _, _ = max_tilt(system, ctrl, "theta", np.pi / 2, x_op=x_op, duration=3.0)
    assert 0.3 < up < np.pi / 2 and down == pytest.approx(up, rel=0.02)
    est = estimate_slice(system, ctrl, ("theta", "theta_dot"), ((-1.6, 1.6), (-5.0, 5.0)),
                         x_op=x_op, grid=12, max_samples=3000, duration=3.0)
    assert est.levels >= 2 and 0.1 < est.fraction_caught < 0.9
    # Refinement puts the runs at the boundary: most samples beyond the first grid (169)
    # have neighbours of both kinds close by.
    assert est.samples > 169 * 3
    # On the line theta_dot = 0, the slice catches exactly what the tilt search found.
    on_axis = np.abs(est.points[:, 1]) < 1e-12
    th, ok = est.points[on_axis, 0], est.caught[on_axis]
    assert np.all(ok[np.abs(th) < 0.95 * up]) and not np.any(ok[np.abs(th) > 1.05 * up])


def test_the_command_reports_plots_and_keeps_its_runs(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    png, table = tmp_path / "roa.png", tmp_path / "roa.parquet"
    assert main(["roa", "cartpole", "--controller", "lqr", "--samples", "1500", "--json",
                 "--certify", "off", "--plot", str(png), "--out", str(table)]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("rho", "certified", "method", "max_tilt", "max_push", "samples",
                "counterexamples", "coverage", "rho_sampled"):
        assert key in out
    assert out["certified"] is False and out["rho"] is None  # without the proof: an estimate
    assert out["slice"] == ["theta", "theta_dot"] and out["samples"] > 1000
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import pyarrow.parquet as pq

    runs = pq.read_table(table).to_pydict()
    assert len(runs["caught"]) == out["samples"] and "theta_0" in runs
    # The sampled level holds: no start below it was lost.
    x = np.column_stack([runs[f"{n}_0"] for n in ("x", "theta", "x_dot", "theta_dot")])
    S = design(get_system("cartpole"), rate=200.0).S
    V = np.einsum("ij,jk,ik->i", x, S, x)
    assert np.all(np.array(runs["caught"])[out["rho_sampled"] > V])


@pytest.mark.parametrize(("argv", "words"), [
    (["--slice", "theta"], "two different states"),
    (["--slice", "theta,spin"], "no state 'spin'"),
    (["--range", "theta=1:0"], "LO < HI"),
    (["--samples", "5"], ">= 100"),
    (["--out", "x.csv"], "FILE.parquet"),
    (["--controller", "none"], "open loop"),
    (["--boxes", "10"], ">= 1000"),
    (["--falsify", "-3"], "--falsify"),
    (["--certify", "maybe"], "invalid choice"),
])
def test_bad_options_are_one_line_and_status_2(argv: list[str], words: str,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["roa", "cartpole", *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1
