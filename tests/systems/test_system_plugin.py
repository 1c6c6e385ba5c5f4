"""A new system is one file: a throwaway rig in a temporary folder, found through its entry
point, joins the catalogue and runs through simulate (LQG and its swing-up), batch, a study,
the environment, its drawing and the export.

The rig (``pointcart``): a bob on a massless rod on a cart, with its drawing and its swing-up
stated in its definition. Its independent check: it is the catalogue's cart-pole with a point
mass (``I_p = 0``), derived again from scratch, so the two must give the same dynamics.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from tests.support.export import make_check
from tests.support.plugins import cli, install

RIG_MODULE = '''
"""A rig of one's own, in one file: a cart with a bob on a massless rod, its drawing and its
swing-up."""

import math

import numpy as np

from equilibrist.mechanics.spec import (Input, OperatingPoint, Scenario, SwingUp, SystemSpec,
                                        friction, positive)
from equilibrist.systems.registry import register
from equilibrist.viz.drawing import COLORS, Scene, Shape, bar, circle, lean, rect

SPEC = SystemSpec(
    name="pointcart",
    title="Bob on a cart",
    description="A cart on a track balancing a bob on a massless rod.",
    coordinates=("x", "theta"),
    units={"x": "m", "theta": "rad"},
    parameters=(
        positive("M", 2.0, "kg", "cart mass"),
        positive("m", 0.5, "kg", "bob mass"),
        positive("L", 0.6, "m", "rod length, pivot to bob"),
        friction("b", 0.1, "N*s/m", "cart viscous friction"),
        positive("g", 9.81, "m/s^2", "gravitational acceleration"),
        positive("x_max", 1.0, "m", "half length of the track"),
    ),
    inputs=(Input("F", "N", "force on the cart, +x", -40.0, 40.0),),
    outputs=("x", "theta"),
    operating_point=OperatingPoint(state={}, inputs={"F": 0.0}),
    region={"theta": (-math.pi / 2, math.pi / 2), "x": (-1.0, 1.0)},
    design_scales={"x": 0.2, "theta": 0.1, "x_dot": 0.5, "theta_dot": 1.0, "F": 10.0},
    sensor_noise={"x": 1e-4, "theta": 1e-3},
    process_noise={"x_dot": 0.02, "theta_dot": 0.02},
    control_rate=200.0,
    hanging={"theta": math.pi},
    swingup=SwingUp("cart", {"k_energy": 5.0, "a_max": 6.0, "k_x": 6.0, "k_v": 4.0,
                              "catch_fraction": 3.0}),
    drawing=f"{__name__}:PointcartScene",
    scenario=Scenario(duration=4.0, start={"theta": 0.05}, push=10.0, push_name="a 10 N shove"),
)


class PointcartScene(Scene):
    """The cart as a box on the track, the rod and the bob."""

    caption = "cart position x; rod angle θ clockwise from up; arrow: force F"

    def shapes(self, x, u, trail=None):
        size = self.params["L"]
        pivot = np.array([self.q(x, "x"), 0.0])
        bob = pivot + size * lean(self.q(x, "theta"))
        return [Shape("cart", "fill", rect(pivot[0], -0.1 * size, 0.4 * size, 0.2 * size),
                      COLORS["body"], z=2),
                Shape("rod", "fill", bar(pivot, bob, 0.03 * size), COLORS["link"], z=4),
                Shape("bob", "fill", circle(bob, 0.08 * size, 20), COLORS["pivot"], z=6)]

    def reach(self, states):
        L = self.params["L"]
        xs = states[:, 0]
        return (float(xs.min()) - 1.2 * L, float(xs.max()) + 1.2 * L, -1.2 * L, 1.2 * L)


@register(SPEC)
def derive(d):
    from sympy.physics import mechanics as me

    x, theta = d.q
    x_dot, theta_dot = d.qd
    p, F = d.p, d.u["F"]
    N, O = d.N, d.O
    rod = N.orientnew("rod", "Axis", (-theta, N.z))
    rod.set_ang_vel(N, -theta_dot * N.z)
    pivot = O.locatenew("pivot", x * N.x)
    pivot.set_vel(N, x_dot * N.x)
    bob = pivot.locatenew("bob", p["L"] * rod.y)
    bob.set_vel(N, bob.pos_from(O).dt(N))
    cart, ball = me.Particle("cart", pivot, p["M"]), me.Particle("ball", bob, p["m"])
    loads = [(pivot, (F - p["b"] * x_dot) * N.x - p["M"] * p["g"] * N.y),
             (bob, -p["m"] * p["g"] * N.y)]
    energy = cart.kinetic_energy(N) + ball.kinetic_energy(N) + p["m"] * p["g"] * bob.pos_from(O).dot(N.y)
    return d.kane(bodies=[cart, ball], loads=loads, energy=energy)
'''


@pytest.fixture(scope="module")
def plugin(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    return install(tmp_path_factory.mktemp("rig"), "pointcart_rig", RIG_MODULE,
                   "equilibrist.systems", "pointcart")


def _python(env: dict[str, str], script: str) -> str:
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(script)], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_it_joins_the_catalogue_with_the_cartpoles_dynamics(plugin) -> None:
    listed = json.loads(cli(plugin, "systems", "--json").stdout)
    assert list(listed)[-1] == "pointcart"  # no position stated: after the numbered ones
    out = _python(plugin, """
        import numpy as np
        from equilibrist import get_system
        mine = get_system("pointcart", M=2.0, m=0.5, L=0.6, b=0.1)
        ref = get_system("cartpole", m_c=2.0, m_p=0.5, l=0.6, I_p=0.0, b_c=0.1, b_p=0.0, g=9.81)
        rng = np.random.default_rng(3)
        worst = 0.0
        for _ in range(20):
            x, u = rng.uniform(-2, 2, 4), rng.uniform(-30, 30, 1)
            worst = max(worst, float(np.abs(mine.f(x, u) - ref.f(x, u)).max()))
        print(worst)
    """)
    assert float(out) < 1e-12


def test_simulate_balances_it_and_swings_it_up(plugin) -> None:
    run = cli(plugin, "simulate", "pointcart", "--duration", "3", "--x0", "theta=0.1", "--json")
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["stayed_up"] is True
    up = cli(plugin, "simulate", "pointcart", "--controller", "swingup", "--x0", "theta=3.14",
              "--duration", "10", "--json")
    assert up.returncode == 0, up.stderr
    result = json.loads(up.stdout)
    # Caught upright, a whole number of turns from where it started.
    assert result["fell"] is False and abs(math.remainder(result["final_error"]["theta"], 2 * math.pi)) < 0.01


def test_batch_and_a_study_run_it_in_worker_processes(plugin, tmp_path: Path) -> None:
    batch = cli(plugin, "batch", "pointcart", "--runs", "6", "--duration", "1", "--workers", "2",
                 "--json")
    assert batch.returncode == 0, batch.stderr
    assert json.loads(batch.stdout)["stayed_up"] == 6
    out = tmp_path / "study.parquet"
    study = cli(plugin, "sweep", "pointcart", "--vary", "m=0.3,0.6", "--runs", "4",
                 "--duration", "1", "--out", str(out))
    assert study.returncode == 0, study.stderr
    import pyarrow.parquet as pq

    table = pq.read_table(out).to_pydict()
    assert table["status"] == ["ok", "ok"] and table["fraction_up"] == [1.0, 1.0]


def test_its_environment_and_its_own_drawing(plugin, tmp_path: Path) -> None:
    out = _python(plugin, f"""
        import gymnasium as gym
        import numpy as np
        import equilibrist.envs
        from equilibrist import get_system
        from equilibrist.viz.scenes import scene_for
        from equilibrist.viz.frames import draw_state
        env = gym.make("equilibrist/pointcart-balance-v0", observe="state")
        obs, _ = env.reset(seed=1)
        obs, reward, terminated, truncated, _ = env.step(np.zeros(1, dtype=np.float32))
        system = get_system("pointcart")
        png = draw_state(system, np.array([0.1, 0.3, 0.0, 0.0]), {str(tmp_path / "rig.png")!r})
        print(obs.shape[0], type(scene_for(system)).__name__, png.stat().st_size > 1000)
    """)
    assert out.split() == ["4", "PointcartScene", "True"]


def test_it_exports_as_c_that_make_check_proves_bit_for_bit(plugin, tmp_path: Path) -> None:
    out = tmp_path / "rig"
    done = cli(plugin, "export", "pointcart", "--duration", "1", "--out", str(out), "--json")
    assert done.returncode == 0, done.stderr
    make_check(out)
