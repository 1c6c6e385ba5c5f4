"""``--at`` wherever a design is made: the demo's tour and the environments (issue 26, item 1).

The seesaw balances at any tilt its drone motor can hold (``equilibrium(state={"theta":
0.2})`` solves its thrust), so it has equilibria other than its canonical level one.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.numeric.lookup import get_system
from equilibrist.tasks import get_task

TILT = 0.2  # rad: an equilibrium of the seesaw other than its canonical theta = 0


# -- the demo -----------------------------------------------------------------------------------

def test_demo_at_designs_there_and_runs_its_scenario_about_it(tmp_path: Path, capsys) -> None:
    from equilibrist.sim.result import SimResult

    out = tmp_path / "report"
    assert main(["demo", "seesaw", "--at", f"theta={TILT}", "--out", str(out), "--jobs", "1"]) == 0
    assert "seesaw" in capsys.readouterr().out
    run = SimResult.load(next(out.glob("*/run.npz")))
    theta = run.state("theta")
    assert run.x_op[0] == pytest.approx(TILT)
    assert not run.fell
    # The scenario's start (0.15 rad below the operating point) and its reference step
    # (0.1 rad up) are about the tilted point, not about level.
    assert theta[0] == pytest.approx(TILT - 0.15, abs=1e-9)
    assert np.mean(theta[-100:]) == pytest.approx(TILT + 0.1, abs=0.02)
    assert (out / "index.html").exists()


@pytest.mark.parametrize(("argv", "message"), [
    (["--at", "theta=0.2"], "--at needs a SYSTEM"),
    (["seesaw", "--at", "phi=0.2"], "no state 'phi'"),
    (["seesaw", "--at", "theta=abc"], "not a number"),
    (["seesaw", "--at", "theta=3"], "outside its limits"),
])
def test_demo_refuses_a_bad_at_in_one_line(tmp_path: Path, capsys, argv: list[str],
                                           message: str) -> None:
    assert main(["demo", *argv, "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "r").exists()


# -- the task -----------------------------------------------------------------------------------

def test_the_balance_task_moves_with_its_operating_point() -> None:
    seesaw = get_system("seesaw")
    task = get_task(seesaw, "balance", at={"theta": TILT})
    eq = seesaw.equilibrium(state={"theta": TILT})
    assert task.x_op.tolist() == pytest.approx(eq.x.tolist())
    assert task.u_op.tolist() == pytest.approx(eq.u.tolist())
    assert task.start[0] == pytest.approx(TILT)
    assert task.cost(task.x_op, task.u_op) == pytest.approx(0.0)
    assert task.region == dict(seesaw.spec.region)  # inside the region: it stays
    # Outside the region (the cart-pole hanging), the region moves with the point.
    hanging = get_task(get_system("cartpole"), "balance", at={"theta": math.pi})
    low, high = hanging.region["theta"]
    assert (low, high) == pytest.approx((math.pi / 2, 3 * math.pi / 2))
    assert not hanging.fallen(hanging.start)


# -- the environments ---------------------------------------------------------------------------

def test_an_environment_at_another_point_balances_with_its_expert_there() -> None:
    gymnasium = pytest.importorskip("gymnasium")
    import equilibrist.envs  # noqa: F401  (registers the ids)
    from equilibrist.envs.expert import expert

    env = gymnasium.make("equilibrist/seesaw-balance-v0", at={"theta": TILT})
    core = env.unwrapped.core
    assert core.task.x_op[0] == pytest.approx(TILT)
    assert core.describe()["at"] == {"theta": TILT}
    policy = expert(env)
    assert policy.controller.design.plant.x0[0] == pytest.approx(TILT)
    obs, _ = env.reset(seed=3)
    policy.reset()
    assert abs(env.unwrapped.state[0] - TILT) < 0.25 * 0.2 + 1e-9  # drawn about the point
    rewards, thetas = [], []
    while True:
        obs, reward, terminated, truncated, _ = env.step(policy(obs))
        rewards.append(reward)
        thetas.append(env.unwrapped.state[0])
        if terminated or truncated:
            break
    assert truncated and not terminated
    assert np.mean(thetas[-100:]) == pytest.approx(TILT, abs=0.01)
    # The reward's cost is about the point: near it, each step earns almost the whole bonus.
    assert np.mean(rewards[-100:]) > 0.9 * core.alive_bonus / core.rate
    env.close()


def test_the_vector_environment_takes_at() -> None:
    from equilibrist.envs import EquilibristVectorEnv

    venv = EquilibristVectorEnv(2, "seesaw", "balance", at={"theta": TILT})
    assert venv.core.task.x_op[0] == pytest.approx(TILT)
    venv.reset(seed=0)
    assert np.all(np.abs(venv.states[:, 0] - TILT) <= 0.25 * 0.2 + 1e-9)  # drawn about the point
    venv.close()


@pytest.mark.parametrize(("at", "message"), [
    ({"phi": 0.1}, "seesaw has no state 'phi'"),
    ({"theta": "level"}, "theta = 'level' is not a finite number"),
    ({"theta": math.inf}, "is not a finite number"),
    ([("theta", 0.1)], "expected a mapping"),
    ({"theta": 3.0}, "outside its limits"),
])
def test_an_environment_refuses_a_bad_at_in_one_error(at: object, message: str) -> None:
    from equilibrist.envs import EnvError, EquilibristEnv

    with pytest.raises(EnvError, match=r"^at") as info:
        EquilibristEnv("seesaw", "balance", at=at)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_the_swingup_task_is_not_posed_elsewhere() -> None:
    from equilibrist.envs import EnvError, EquilibristEnv

    with pytest.raises(EnvError, match="balance task only"):
        EquilibristEnv("cartpole", "swingup", at={"x": 0.3})
