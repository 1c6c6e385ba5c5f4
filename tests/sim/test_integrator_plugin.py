"""A new integrator is one entry of the table (equilibrist.sim.integrators), and every
consumer steps with it.

The test registers explicit Euler, whose C comes with its entry, and runs it through
``simulate``, ``simulate_batch``, the single and the vector environment, identification's
multiple shooting and the command line's ``--integrator``. Independent truth: Euler's
steps computed here in numpy from the system's own ``f`` (``x += h f(x, u, p)``), which
differ from RK4's by about ``h^2`` a step, far above the tolerance; and the table's orders,
checked by the error's convergence against scipy's ``solve_ivp`` at a tight tolerance.
"""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterator

import numpy as np
import pytest

from equilibrist.cli.main import build_parser
from equilibrist.envs.env import EquilibristEnv
from equilibrist.envs.vector import EquilibristVectorEnv
from equilibrist.ident.kernel import load_shooting
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import integrators
from equilibrist.sim.batch import simulate_batch
from equilibrist.sim.run import simulate

EULER_C = """
static inline int eq_euler_step(double *x, const double *u, const double *p, const double *w,
                                int64_t nw, double h, const eq_step_ctx *c)
{
    double *k = EQ_WORK(c, EQ_EULER_K);
    int i;
    (void)nw;
    eq_f(x, u, p, k);
    for (i = 0; i < EQ_N; i++) x[i] += h * (k[i] + w[i]);
    return 1;
}
"""

EULER = integrators.Integrator(
    name="euler", help="explicit Euler (a test's)", order=1, fixed_step=True,
    step="eq_euler_step", rows=("k",), source=EULER_C)

SYSTEM = "cartpole"
RATE = 50.0
N_SUB = 4
H = 1.0 / (RATE * N_SUB)
X0 = np.array([0.05, 0.1, -0.2, 0.3])


@pytest.fixture
def euler() -> Iterator[str]:
    integrators.register(EULER)
    try:
        yield EULER.name
    finally:
        integrators.unregister(EULER.name)


def _euler(system, x: np.ndarray, u: np.ndarray, steps: int, h: float = H,
           p: np.ndarray | None = None) -> np.ndarray:
    """*steps* explicit Euler steps of the system's f (numpy, the Python model)."""
    fn = system.functions.f
    pv = np.array(system.p if p is None else p, dtype=float)
    x = np.array(x, dtype=float)
    k = np.empty_like(x)
    for _ in range(steps):
        fn(x, np.asarray(u, dtype=float), pv, k)
        x = x + h * k
    return x


def _close(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)


def test_the_table_offers_it(euler):
    assert euler in integrators.names()
    assert integrators.check(euler) is None
    assert "linear" not in integrators.names()  # the linear plant's step, not a user's choice
    with pytest.raises(ValueError, match="exists"):
        integrators.register(EULER)


def test_simulate_steps_with_it(euler):
    system = get_system(SYSTEM)
    res = simulate(system, None, duration=0.1, rate=RATE, physics_step=H, integrator=euler,
                   x0=X0, region={})
    u = res.applied[0]
    assert np.all(res.applied == u)  # open loop: the operating point's input, held
    for k in range(1, res.n_rows):
        _close(res.states[k], _euler(system, X0, u, k * N_SUB))
    rk4 = simulate(system, None, duration=0.1, rate=RATE, physics_step=H, x0=X0, region={})
    assert np.max(np.abs(rk4.final_state - res.final_state)) > 1e-6  # not RK4's steps


def test_batch_steps_with_it(euler):
    system = get_system(SYSTEM)
    x0s = np.array([X0, -X0, 0.5 * X0])
    res = simulate(system, None, duration=0.1, rate=RATE, physics_step=H, x0=X0, region={})
    batch = simulate_batch(system, None, runs=3, duration=0.1, rate=RATE, physics_step=H,
                           integrator=euler, x0=x0s, region={}, workers=1)
    steps = (res.n_rows - 1) * N_SUB
    for i in range(3):
        _close(batch.final_state[i], _euler(system, x0s[i], res.applied[0], steps))


def _env_options(euler: str) -> dict[str, object]:
    return dict(rate=RATE, physics_step=H, noise=False, observe="state",
                action_units="physical", integrator=euler)


def test_the_environments_step_with_it(euler):
    system = get_system(SYSTEM)
    env = EquilibristEnv(SYSTEM, "balance", **_env_options(euler))
    assert env.unwrapped.core.describe()["integrator"] == euler
    obs, _ = env.reset(seed=1)
    action = np.array([1.5])
    after, *_ = env.step(action)
    _close(after, _euler(system, obs, action, N_SUB))

    vec = EquilibristVectorEnv(9, SYSTEM, "balance", **_env_options(euler))
    assert vec.core.kernel.lanes == 1  # the lanes step RK4 only: copies one at a time
    obs, _ = vec.reset(seed=2)
    actions = np.linspace(-2.0, 2.0, 9)[:, None]
    after, *_ = vec.step(actions)
    for i in range(9):
        _close(after[i], _euler(system, obs[i], actions[i], N_SUB))


def test_the_environments_refuse_an_unknown_integrator():
    with pytest.raises(ValueError, match="integrator='euler2': expected one of rk4, adaptive"):
        EquilibristEnv(SYSTEM, "balance", integrator="euler2")


def test_identification_shoots_with_it(euler):
    system = get_system(SYSTEM)
    n, n_rows = system.n_states, 6
    t = np.arange(n_rows) / RATE
    u = np.linspace(-1.0, 1.0, n_rows)[:, None]
    n_sub = np.full(n_rows - 1, N_SUB, dtype=np.int64)
    bounds = np.array([0, 3, n_rows - 1], dtype=np.int64)
    p = np.array(system.p, dtype=float)
    XS = np.array([[X0, -X0]])
    c_idx = np.arange(n, dtype=np.int64)
    yhat = np.zeros((1, n_rows, n))
    xend = np.zeros((1, 2, n))
    load_shooting(system, euler).shoot_many(p[None, :], XS, bounds, t, u, n_sub, c_idx, yhat,
                                             xend)
    for s in range(2):
        x = XS[0, s]
        for k in range(bounds[s], bounds[s + 1]):
            _close(yhat[0, k], x)
            x = _euler(system, x, u[k], N_SUB, h=(t[k + 1] - t[k]) / N_SUB, p=p)
        _close(xend[0, s], x)


def test_the_command_line_offers_it(euler):
    parser = build_parser("simulate")
    args = parser.parse_args(["simulate", SYSTEM, "--integrator", euler])
    assert args.integrator == euler
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit):
        parser.parse_args(["simulate", "--help"])
    shown = " ".join(out.getvalue().split())  # the help as one line
    assert "--integrator {rk4,adaptive,euler}" in shown
    assert "euler: explicit Euler (a test's)" in shown


@pytest.mark.parametrize("name", ["euler", "rk4"])
def test_the_table_says_each_fixed_step_order(euler, name):
    """The global error at the end of an open-loop run shrinks as h ** order."""
    from scipy.integrate import solve_ivp

    system = get_system(SYSTEM)
    order = integrators.get(name).order
    u = simulate(system, None, duration=0.2, rate=RATE, x0=X0, region={}).applied[0]

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        out = np.empty(4)
        system.functions.f(x, u, np.array(system.p, dtype=float), out)
        return out

    truth = solve_ivp(rhs, (0.0, 0.2), X0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    errors = []
    for n_sub in (2, 4):
        res = simulate(system, None, duration=0.2, rate=RATE, physics_step=1.0 / (RATE * n_sub),
                       integrator=name, x0=X0, region={})
        errors.append(np.max(np.abs(res.final_state - truth)))
    ratio = np.log2(errors[0] / errors[1])
    assert abs(ratio - order) < 0.3, (errors, ratio)


@pytest.mark.parametrize("name", ["rk4", "adaptive", "euler"])
def test_an_environment_rollout_is_simulate_to_the_bit(euler, name):
    """Each integrator of the table: the environment's periods are simulate's samples."""
    system = get_system(SYSTEM)
    env = EquilibristEnv(SYSTEM, "balance", noise=False, observe="state",
                         action_units="physical", integrator=name)
    obs, _ = env.reset(seed=4)
    states = [obs]
    for _ in range(5):
        states.append(env.step(np.zeros(1))[0])
    rate = env.unwrapped.core.rate
    ref = simulate(system, None, duration=5 / rate, rate=rate, integrator=name, x0=obs,
                   region={})
    assert np.all(ref.applied == 0.0)
    assert np.array_equal(np.array(states), ref.states[:6])
