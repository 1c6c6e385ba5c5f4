"""A new controller kind is one file: a throwaway kind in a temporary folder, found through
its entry point, runs through simulate, batch, a study, the environment and the export.

The kind (``softlqr``): the design's LQR gain through a ``tanh`` of width ``--softness``
(a saturation that bends instead of clipping). Its independent check: as the width grows,
``s tanh(v / s)`` tends to ``v``, so a wide one must run as ``--controller lqr`` does.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from tests.support.export import make_check
from tests.support.plugins import cli, install

KIND_MODULE = '''
"""A controller kind of one's own: the LQR through a tanh of width --softness."""

from equilibrist.controllers.kinds import ControllerKind, Option

SOURCE = """
import math


def output(t, z, y, r, params, u_out):
    n = int(params[0])
    v = 0.0
    for i in range(n):
        v = v - params[1 + i] * (y[i] - params[1 + n + i])
    s = params[1 + 2 * n]
    u_out[0] = params[2 + 2 * n] + s * math.tanh(v / s)


def update(t, z, y, r, u_applied, params, z_out):
    return
"""


def _width(text):
    value = float(text)
    if not value > 0:
        raise ValueError(text)
    return value


def build(request):
    import numpy as np

    from equilibrist.control.nonlinear import NonlinearController

    d = request.design()
    plant, system = d.plant, request.system
    n = system.n_states
    s = float(request.options.get("softness", 10.0))
    params = np.concatenate([[n], np.asarray(d.K, float)[0], plant.x0, [s], plant.u0])
    return NonlinearController(
        name="softlqr", source=SOURCE, params=params, z0=np.zeros(0),
        rate=float(d.rate), x_op=plant.x0, u_op=plant.u0, state_names=system.state_names,
        input_names=system.input_names, output_names=system.state_names,
        settings={"softness": s})


def applies(system):
    if system.n_inputs != 1 or system.n_states != 4:
        return (f"{system.key} has {system.n_states} states and {system.n_inputs} inputs: "
                "softlqr drives one input of a four-state rig")
    return None


KIND = ControllerKind(
    name="softlqr", label="Soft LQR (tanh)", help="the LQR through a tanh of width --softness",
    build=build, applies=applies, noise="spec",
    options=(Option("--softness", "width of softlqr's tanh, in the input's unit (default 10)",
                    parse=_width, expected="a positive number", metavar="U"),),
)
'''


@pytest.fixture(scope="module")
def plugin(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    return install(tmp_path_factory.mktemp("kind"), "softlqr_kind", KIND_MODULE,
                   "equilibrist.controllers", "softlqr", "softlqr_kind:KIND")


def test_simulate_offers_it_takes_its_option_and_a_wide_one_runs_as_the_lqr(plugin) -> None:
    helped = cli(plugin, "simulate", "--help")
    assert "softlqr" in helped.stdout and "--softness" in helped.stdout
    common = ["--duration", "2", "--x0", "theta=0.15", "--noise", "off", "--json"]
    soft = cli(plugin, "simulate", "cartpole", "--controller", "softlqr", "--softness", "1e9",
                *common)
    assert soft.returncode == 0, soft.stderr
    lqr = cli(plugin, "simulate", "cartpole", "--controller", "lqr", *common)
    a, b = json.loads(soft.stdout), json.loads(lqr.stdout)
    assert a["fell"] is False
    assert a["rms_input"] == pytest.approx(b["rms_input"], rel=1e-9)
    assert a["peak_command"] == pytest.approx(b["peak_command"], rel=1e-9)
    # A narrow tanh bends the command: the peak is bounded by the width.
    narrow = json.loads(cli(plugin, "simulate", "cartpole", "--controller", "softlqr",
                             "--softness", "5", *common).stdout)
    assert narrow["peak_command"]["F"] <= 5.0 + 1e-9 < b["peak_command"]["F"]


def test_its_options_and_where_it_applies_are_refused_in_one_line(plugin) -> None:
    bad = cli(plugin, "simulate", "cartpole", "--controller", "softlqr", "--softness", "abc")
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "equilibrist: error: --softness 'abc': expected a positive number"]
    other = cli(plugin, "simulate", "cartpole", "--controller", "lqr", "--softness", "3")
    assert other.returncode == 2 and "the lqr controller takes none" in other.stderr
    two = cli(plugin, "simulate", "double_cartpole", "--controller", "softlqr")
    assert two.returncode == 2 and "softlqr drives one input of a four-state" in two.stderr
    assert "Traceback" not in bad.stderr + other.stderr + two.stderr


def test_batch_and_a_study_run_it_in_worker_processes(plugin, tmp_path: Path) -> None:
    batch = cli(plugin, "batch", "cartpole", "--controller", "softlqr", "--runs", "6",
                 "--duration", "1", "--workers", "2", "--json")
    assert batch.returncode == 0, batch.stderr
    assert json.loads(batch.stdout)["stayed_up"] == 6
    out = tmp_path / "study.parquet"
    study = cli(plugin, "sweep", "cartpole", "--vary", "controller=lqr,softlqr", "--runs", "4",
                 "--duration", "1", "--out", str(out))
    assert study.returncode == 0, study.stderr
    import pyarrow.parquet as pq

    table = pq.read_table(out).to_pydict()
    assert table["controller"] == ["lqr", "softlqr"]
    assert table["status"] == ["ok", "ok"] and table["fraction_up"] == [1.0, 1.0]


def test_the_environment_takes_it_as_its_expert(plugin) -> None:
    script = textwrap.dedent('''
        import gymnasium as gym
        import equilibrist.envs
        from equilibrist.envs.expert import expert
        env = gym.make("equilibrist/cartpole-balance-v0", observe="state")
        policy = expert(env, "softlqr", options={"softness": 20.0})
        obs, _ = env.reset(seed=2)
        policy.reset()
        steps, done = 0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            steps += 1
            done = terminated or truncated
        print(steps, terminated, abs(env.unwrapped.state[1]) < 0.01)
    ''')
    proc = subprocess.run([sys.executable, "-c", script], env=plugin, capture_output=True,
                          text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    steps, terminated, upright = proc.stdout.split()
    assert int(steps) > 100 and terminated == "False" and upright == "True"


def test_it_exports_as_c_that_make_check_proves_bit_for_bit(plugin, tmp_path: Path) -> None:

    out = tmp_path / "soft"
    done = cli(plugin, "export", "cartpole", "--controller", "softlqr", "--softness", "8",
                "--duration", "1", "--out", str(out), "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["controller"] == "softlqr"
    assert "tanh(" in (out / "softlqr.c").read_text()
    make_check(out)
