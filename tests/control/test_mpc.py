"""Constrained MPC: the unconstrained case is the LQR, the hard limits hold, the track is kept."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.control.mpc import mpc
from equilibrist.control.mpc_runtime import MPCRuntime
from equilibrist.control.riccati import dlqr
from equilibrist.controllers.kinds import ControllerRequest, build_controller
from equilibrist.errors import ControllerError
from equilibrist.sim.run import simulate


@pytest.fixture(scope="module")
def cart() -> tuple[object, object]:
    system = get_system("cartpole")
    return system, design(system, rate=200.0)


def _small_states(n: int, seed: int) -> np.ndarray:
    scale = np.array([0.05, 0.02, 0.05, 0.05])
    return np.random.default_rng(seed).normal(size=(n, 4)) * scale


@pytest.mark.parametrize("exact", [True, False])
def test_unconstrained_command_is_the_discrete_lqr(cart: tuple[object, object], exact: bool) -> None:
    """Away from every limit the first move is -K dx, K from an independent dlqr call."""
    system, d = cart
    ctrl = mpc(system, design=d, horizon=30, estimator="state")  # type: ignore[arg-type]
    K = dlqr(d.discrete.A, d.discrete.B, d.Q, d.R).K  # type: ignore[attr-defined]
    rt = MPCRuntime(ctrl, exact_unconstrained=exact)
    for dx in _small_states(25, 1):
        assert rt.lqr_feasible(dx)
        du = rt.solve(dx)
        np.testing.assert_allclose(du, -K @ dx, rtol=0, atol=1e-8)
    assert rt.last_status == ("unconstrained" if exact else "solved")


def test_terminal_cost_makes_any_horizon_the_lqr(cart: tuple[object, object]) -> None:
    system, d = cart
    dx = _small_states(1, 2)[0]
    moves = [MPCRuntime(mpc(system, design=d, horizon=h, estimator="state"), exact_unconstrained=False).solve(dx)  # type: ignore[arg-type]
             for h in (1, 5, 40)]
    for du in moves[1:]:
        np.testing.assert_allclose(du, moves[0], rtol=0, atol=1e-8)


def test_closed_loop_equals_lqr_closed_loop(cart: tuple[object, object]) -> None:
    """Same run, MPC (every sample through DAQP) and LQR: states agree to 1e-6 of each state's range."""
    from equilibrist.control.linear import LinearController

    system, d = cart
    lqr = LinearController.from_design(d, kind="lqr")  # type: ignore[arg-type]
    ctrl = MPCRuntime(mpc(system, design=d, horizon=20, estimator="state"), exact_unconstrained=False)  # type: ignore[arg-type]
    x0 = {"x": 0.05, "theta": 0.03}
    a = simulate(system, lqr, duration=2.0, x0=x0)
    b = simulate(system, ctrl, duration=2.0, x0=x0)
    span = np.ptp(a.states, axis=0)
    assert np.all(np.abs(a.states - b.states) <= 1e-6 * span)


def test_commands_stay_inside_the_hard_limits(cart: tuple[object, object]) -> None:
    system, d = cart
    ctrl = mpc(system, design=d, horizon=30, estimator="state")  # type: ignore[arg-type]
    res = simulate(system, ctrl.runtime(), duration=2.0,
                   x0={"x": 0.3, "theta": 0.5, "theta_dot": 1.0}, region={})
    lo, hi = system.input_limits
    assert np.all(res.commanded >= lo - 1e-12) and np.all(res.commanded <= hi + 1e-12)
    assert np.any(np.isclose(np.abs(res.commanded), hi[0])), "the case must reach a limit"


def test_keeps_the_track_where_the_clipped_lqr_leaves_it() -> None:
    """The cart at the centre moving at 2 m/s: the clipped LQR runs off the 1 m track, the MPC
    (50 Hz, 40 samples = 0.8 s ahead, track constrained to 0.95 m) stops in time and balances."""
    from equilibrist.control.linear import LinearController

    system = get_system("cartpole")
    d = design(system, rate=50.0)
    x0 = {"x": 0.0, "x_dot": 2.0, "theta": 0.0}
    region = {"x": (-1.0, 1.0), "theta": (-1.2, 1.2)}
    lqr = simulate(system, LinearController.from_design(d, kind="lqr"), duration=4.0, x0=x0,
                   region=region)
    assert lqr.fell and lqr.fell_state == "x"
    ctrl = mpc(system, design=d, horizon=40, estimator="state",
               constraints={"x": (-0.95, 0.95), "theta": (-1.2, 1.2)})
    res = simulate(system, ctrl.runtime(), duration=4.0, x0=x0, region=region)
    assert not res.fell
    assert np.max(np.abs(res.states[:, 0])) <= 0.96
    assert abs(res.final_state[1]) < 0.05


def test_with_the_kalman_filter_in_front() -> None:
    system = get_system("cartpole")
    d = design(system, rate=200.0)
    ctrl = mpc(system, design=d, horizon=10, estimator="kalman")
    assert ctrl.estimator == "kalman" and ctrl.outputs == ("x", "theta")
    from equilibrist.control.linear import LinearController

    lqg = LinearController.from_design(d, kind="lqg")
    x0 = {"x": 0.05, "theta": 0.02}
    a = simulate(system, lqg, duration=1.0, x0=x0)
    b = simulate(system, MPCRuntime(ctrl, exact_unconstrained=False), duration=1.0, x0=x0)
    span = np.ptp(a.states, axis=0)
    assert np.all(np.abs(a.states - b.states) <= 1e-6 * span)


def test_bad_options_are_one_line() -> None:
    system = get_system("cartpole")
    for kwargs, word in (({"horizon": 0}, "horizon"), ({"estimator": "magic"}, "estimator"),
                         ({"constraints": {"nope": (0, 1)}}, "nope")):
        with pytest.raises(ControllerError, match=word) as info:
            mpc(system, **kwargs)  # type: ignore[arg-type]
        assert "\n" not in str(info.value)


def test_registered() -> None:
    rt = build_controller("mpc", ControllerRequest(system=get_system("cartpole"), rate=None,
                                                   options={"horizon": 12}))
    assert isinstance(rt, MPCRuntime) and rt.ctrl.problem.horizon == 12


def test_command_line_horizon(capsys: pytest.CaptureFixture[str]) -> None:
    # main() in this process: the option's parsing and its one-line refusal are what is
    # tested (the console script's exit status in a process of its own is test_cli_core's).
    from equilibrist.cli.main import main

    code = main(["simulate", "cartpole", "--controller", "mpc", "--horizon", "0"])
    err = capsys.readouterr().err
    assert code == 2 and "--horizon" in err
    assert err.strip().count("\n") == 0
    code = main(["simulate", "cartpole", "--controller", "mpc", "--horizon", "12",
                 "--duration", "0.5", "--x0", "theta=0.05", "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    assert '"stayed_up": true' in out.out


@pytest.mark.parametrize("estimator", ["kalman", "state"])
def test_survives_every_push_the_clipped_lqr_survives(estimator: str) -> None:
    """Cart-pole, 200 Hz, default horizon and soft track bound: pushes of 50..400 N for 0.1 s,
    with and without sensor noise. Wherever the clipped LQR on the same information (the LQG's
    Kalman filter in front, or the full state) stays up and ends back on the track, so does the
    MPC. The sweep includes pushes that carry the cart past the track's end (the soft bound
    violated, the case that used to run away)."""
    from equilibrist.control.linear import LinearController
    from equilibrist.sim.events import Pulse
    from equilibrist.sim.noise import Noise

    system = get_system("cartpole")
    d = design(system, rate=200.0)
    x_max = float(system.params["x_max"])
    ref_kind = "lqg" if estimator == "kalman" else "lqr"
    compared = beyond = 0
    for push in range(50, 401, 50):
        for seed in (None, 1, 2):
            kw = {"duration": 6.0, "events": [Pulse(0.5, float(push), 0.1)],
                  "noise": None if seed is None else Noise.from_design(d), "seed": seed or 0}
            ref = simulate(system, LinearController.from_design(d, kind=ref_kind), **kw)  # type: ignore[arg-type]
            if ref.fell or abs(ref.final_state[0]) > x_max:
                continue
            compared += 1
            beyond += bool(np.abs(ref.states[:, 0]).max() > x_max)
            res = simulate(system, mpc(system, design=d, estimator=estimator).runtime(), **kw)  # type: ignore[arg-type]
            assert not res.fell, (push, seed)
            assert abs(res.final_state[0]) < 0.2 * x_max and abs(res.final_state[1]) < 0.05, (push, seed)
    assert compared >= 12 and beyond >= 2


def test_an_unsolved_qp_is_not_applied_blindly(cart: tuple[object, object]) -> None:
    """DAQP stopped one iteration short of a constrained state's solution: no solution, so the
    command is the clipped LQR's (K from an independent dlqr call), the fallback counted, and
    the next sample starts cold (it takes the same iterations again, where a warm start from
    the unfinished working set would take fewer)."""
    system, d = cart
    ctrl = mpc(system, design=d, horizon=30, estimator="state")  # type: ignore[arg-type]
    K = dlqr(d.discrete.A, d.discrete.B, d.Q, d.R).K  # type: ignore[attr-defined]
    dx = np.array([0.95, 0.0, 1.0, 0.0])
    full = MPCRuntime(ctrl)
    assert not full.lqr_feasible(dx)
    full.solve(dx)
    assert full.last_status == "solved" and full.last_iterations > 2
    rt = MPCRuntime(ctrl, iter_limit=full.last_iterations - 1)
    du = rt.solve(dx)
    assert rt.last_status == "iteration limit" and rt.fallbacks == 1
    lo, hi = ctrl.problem.u_lo, ctrl.problem.u_hi
    np.testing.assert_allclose(du, np.clip(-K @ dx, lo, hi), rtol=0, atol=1e-9)
    rt.solve(dx)
    assert rt.last_status == "iteration limit" and rt.fallbacks == 2
    assert rt.last_iterations == full.last_iterations - 1


def _sparse_reference(d: object, dx0: np.ndarray, horizon: int, soft: tuple[int, ...],
                      lo: np.ndarray, hi: np.ndarray, u_lim: float, rho: tuple[float, float]
                      ) -> float:
    """The MPC's QP in its original variables (states, moves, slacks), built here from the
    design's A, B, Q, R and Riccati S alone and solved by an interior-point solver (Clarabel):
    the first move."""
    import clarabel
    from scipy import sparse

    A, B = np.asarray(d.discrete.A), np.asarray(d.discrete.B)  # type: ignore[attr-defined]
    Q, R, P = np.asarray(d.Q), np.asarray(d.R), np.asarray(d.S)  # type: ignore[attr-defined]
    n, m, N, ns = 4, 1, horizon, len(soft)
    nx, nu, nsl = (N + 1) * n, N * m, N * ns
    H = sparse.block_diag([sparse.kron(sparse.eye(N), 2 * Q), 2 * P, sparse.kron(sparse.eye(N), 2 * R),
                           2 * rho[1] * sparse.eye(nsl)], format="csc")
    q = np.concatenate([np.zeros(nx + nu), np.full(nsl, rho[0])])
    dyn = sparse.hstack([sparse.kron(sparse.eye(N + 1), -np.eye(n)) + sparse.kron(sparse.eye(N + 1, k=-1), A),
                         sparse.kron(sparse.vstack([sparse.csc_matrix((1, N)), sparse.eye(N)]), B),
                         sparse.csc_matrix((nx, nsl))])
    C = np.zeros((ns, n))
    for row, i in enumerate(soft):
        C[row, i] = 1.0
    Cx = sparse.kron(sparse.hstack([sparse.csc_matrix((N, 1)), sparse.eye(N)]), C)
    rows = sparse.vstack([
        dyn,
        sparse.hstack([sparse.csc_matrix((nu, nx)), sparse.eye(nu), sparse.csc_matrix((nu, nsl))]),
        sparse.hstack([Cx, sparse.csc_matrix((nsl, nu)), sparse.eye(nsl)]),
        sparse.hstack([Cx, sparse.csc_matrix((nsl, nu)), -sparse.eye(nsl)]),
        sparse.hstack([sparse.csc_matrix((nsl, nx + nu)), sparse.eye(nsl)]),
    ], format="csc")
    # Clarabel's form: rows x + slack = b, the slack in a cone (zero for the model's equations,
    # nonnegative for the bounds: b - rows x >= 0).
    first = np.concatenate([dx0, np.zeros(nx - n)])
    eye_u = sparse.hstack([sparse.csc_matrix((nu, nx)), sparse.eye(nu), sparse.csc_matrix((nu, nsl))])
    soft_lo = sparse.hstack([Cx, sparse.csc_matrix((nsl, nu)), sparse.eye(nsl)])
    soft_hi = sparse.hstack([Cx, sparse.csc_matrix((nsl, nu)), -sparse.eye(nsl)])
    slack = sparse.hstack([sparse.csc_matrix((nsl, nx + nu)), sparse.eye(nsl)])
    rows = sparse.vstack([-dyn, eye_u, -eye_u, -soft_lo, soft_hi, -slack], format="csc")
    b = np.concatenate([first, np.full(2 * nu, u_lim), -np.tile(lo, N), np.tile(hi, N),
                        np.zeros(nsl)])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-12
    solver = clarabel.DefaultSolver(sparse.triu(H, format="csc"), q, rows, b,
                                    [clarabel.ZeroConeT(nx), clarabel.NonnegativeConeT(2 * nu + 3 * nsl)],
                                    settings)
    res = solver.solve()
    assert str(res.status) in ("Solved", "AlmostSolved"), res.status
    return float(res.x[nx])


@pytest.mark.parametrize("dx0", [[0.0, 0.5, 0.0, 0.0], [0.987, -0.141, 0.217, 0.758],
                                 [0.736, -0.249, 2.146, -0.728], [0.797, 0.037, 2.083, -0.761],
                                 [-0.866, -0.015, -1.871, 0.429]])
def test_constrained_move_equals_an_independent_formulation(cart: tuple[object, object],
                                                          dx0: list[float]) -> None:
    """With constraints active (the input at its limit, the track), DAQP's first move on the
    condensed, prestabilized QP equals the original sparse QP's (states, moves and slacks as
    variables) solved by another kind of solver (Clarabel's interior point). The states are
    inside the soft bounds (outside them the MPC widens those bounds: MPCProblem.soft_limits)."""
    system, d = cart
    ctrl = mpc(system, design=d, horizon=30, estimator="state")  # type: ignore[arg-type]
    p = ctrl.problem
    rt = MPCRuntime(ctrl)
    x = np.array(dx0)
    assert not rt.lqr_feasible(x)
    du = float(rt.solve(x)[0])
    assert rt.last_status == "solved"
    ref = _sparse_reference(d, x, 30, p.soft_index, p.soft_lo, p.soft_hi, float(p.u_hi[0]),
                            (p.rho_l1, p.rho_l2))
    assert du == pytest.approx(ref, abs=1e-6 * float(p.u_hi[0]))
