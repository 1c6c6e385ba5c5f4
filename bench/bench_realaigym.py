"""RealAIGym's double-pendulum leaderboards, scored by the benchmark's own code.

Runs in the benchmark's own environment (its ``double_pendulum`` package importable, and
equilibrist with its ``trajopt`` extra), never in the project's: see docs/realaigym.md.

    BENCH=/tmp/realaigym                     # double_pendulum unpacked there
    $BENCH/.venv/bin/python bench/bench_realaigym.py --benchmark $BENCH --board simulation
    $BENCH/.venv/bin/python bench/bench_realaigym.py --benchmark $BENCH --board robustness \
        --robot acrobot                      # 15-25 minutes a robot
    $BENCH/.venv/bin/python bench/bench_realaigym.py --benchmark $BENCH --plant
    $BENCH/.venv/bin/python bench/bench_realaigym.py --benchmark $BENCH --rigs   # other rigs
    $BENCH/.venv/bin/python bench/bench_realaigym.py --benchmark $BENCH --rigs --variant .0 \
        --friction off       # the files without their friction compensation
    .venv/bin/python bench/bench_realaigym.py --policy       # the policy's step, no benchmark

``--board simulation`` copies ``examples/realaigym/con_<robot>.py`` into the board's folder
and runs the board's own ``calculate_leaderboard_score.py`` on it (which simulates, renders
its video and scores with the board's weights); ``--board robustness`` runs the board's
``benchmark_controller.py`` and reads the score of its ``scores.yml``. ``--plant`` holds
``dfki_double_pendulum``'s ``f`` to the benchmark's plants (``SymbolicDoublePendulum``,
``DoublePendulumPlant``) at random states, inputs and parameters.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent / "examples" / "realaigym"
ROBOTS = ("acrobot", "pendubot")
#: The published bests of the v2 boards (real_ai_gym_leaderboard, leaderboards/*_v2.csv).
BESTS = {("acrobot", "simulation"): (0.655, "History SAC"),
         ("acrobot", "robustness"): (0.751, "History SAC"),
         ("pendubot", "simulation"): (0.682, "History SAC"),
         ("pendubot", "robustness"): (0.913, "AR-EAPO")}


#: The robustness board's families, equally weighted in its score.
FAMILIES = ("model", "measurement_noise", "u_noise", "u_responsiveness", "delay", "perturbation")


def _environment() -> dict[str, str]:
    env = dict(os.environ, MPLBACKEND="Agg")
    # The simulation board renders a video through matplotlib's ffmpeg writer, which looks
    # for ffmpeg on the PATH: imageio-ffmpeg's binary, under that name, if there is no other.
    if shutil.which("ffmpeg") is None:
        import tempfile

        import imageio_ffmpeg

        folder = Path(tempfile.mkdtemp(prefix="ffmpeg-"))
        (folder / "ffmpeg").symlink_to(imageio_ffmpeg.get_ffmpeg_exe())
        env["PATH"] = f"{folder}{os.pathsep}{env.get('PATH', '')}"
    src = str(HERE.parent / "src")
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "") if env.get("PYTHONPATH") \
        else src
    return env


def board(benchmark: Path, robot: str, which: str) -> float:
    """The score of ``con_<robot>.py`` on one board, by the board's own script."""
    folder = benchmark / "leaderboard" / robot / f"{which}_v2"
    con = f"con_{robot}.py"
    shutil.copy(EXAMPLES / con, folder / con)
    data = folder / "data" / robot  # the scripts' data/<file name without con_>
    if data.exists():
        shutil.rmtree(data)  # the scripts reuse a run they find
    script = "calculate_leaderboard_score.py" if which == "simulation" else \
        "benchmark_controller.py"
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, script, con], cwd=folder, env=_environment(),
                         capture_output=True, text=True, check=False)
    if run.returncode != 0:
        raise SystemExit(f"{script} failed:\n{run.stderr[-3000:]}")
    if which == "simulation":
        import pandas

        score = float(pandas.read_csv(data / "leaderboard_entry.csv")["RealAI Score"].iloc[0])
    else:
        import yaml

        with open(data / "scores.yml") as fh:
            families = yaml.safe_load(fh)
        # The board's create_leaderboard.py: the mean of its six families' scores.
        score = sum(float(families[k]) for k in FAMILIES) / len(FAMILIES)
        print("  " + ", ".join(f"{k} {100 * float(families[k]):.1f} %" for k in FAMILIES))
    print(f"{robot:9s} {which:11s} {score:.3f}   (best published {BESTS[robot, which][0]:.3f}, "
          f"{BESTS[robot, which][1]}; {time.perf_counter() - t0:.0f} s)", flush=True)
    return score


def plant(benchmark: Path) -> None:
    """The largest relative difference of ``f`` from the benchmark's two plants."""
    from double_pendulum.model.model_parameters import model_parameters
    from double_pendulum.model.plant import DoublePendulumPlant
    from double_pendulum.model.symbolic_plant import SymbolicDoublePendulum

    from equilibrist import get_system
    from equilibrist.systems.dfki_parameters import settings_of

    rng = np.random.default_rng(0)
    path = benchmark / "data/system_identification/identified_parameters/design_C.1"
    for model in ("model_1.0", "model_1.1"):
        for robot, limits in (("acrobot", [0.0, 6.0]), ("pendubot", [6.0, 0.0])):
            mpar = model_parameters(filepath=str(path / model / "model_parameters.yml"))
            mpar.set_torque_limit(limits)
            ours = get_system("dfki_double_pendulum", **settings_of(mpar, robot=robot))
            for cls in (SymbolicDoublePendulum, DoublePendulumPlant):
                theirs = cls(model_pars=mpar)
                worst = 0.0
                for _ in range(200):
                    x = rng.uniform(-4.0, 4.0, 4)
                    u = float(rng.uniform(-6.0, 6.0))
                    both = [0.0, u] if robot == "acrobot" else [u, 0.0]
                    want = np.asarray(theirs.rhs(0.0, x, both), dtype=float)
                    got = ours.f(x, np.array([u]))
                    worst = max(worst, float(np.max(np.abs(got - want)) / np.max(np.abs(want))))
                print(f"{model} {robot:9s} {cls.__name__:22s} max relative difference "
                      f"{worst:.1e}")


#: The rigs of ``double_pendulum``'s ``model_parameters.load_model`` (design, model) besides
#: the boards' C.1 model 1.0: other builds of the rig (link lengths, masses) and other
#: identifications of them.
RIGS = (("design_A.0", "model_1"), ("design_A.0", "model_2"), ("design_B.0", "model_1"),
        ("design_B.0", "model_h2"), ("design_C.0", "model_3"), ("design_C.0", "model_h1"),
        ("design_hD.0", "model_h1"))
#: A model id's suffix: ``.0`` as identified (rotor, damping, Coulomb friction), ``.1``
#: without them (the boards' setting), ``.2`` with damping alone.
VARIANTS = (".1", ".2", ".0")


def rigs(benchmark: Path, robots: list[str], variants: list[str], friction: str | None = None
         ) -> None:
    """The controller files, unchanged, on rigs they were not tuned on: each rig's
    parameters as the benchmark's own ``model_parameters`` loads them, the actuated joint
    limited to the boards' 6 N m, run by the simulation board's own simulator (its plant,
    RK4, 500 Hz, 10 s from hanging at rest). A rig swings up when the board's criterion
    finds a swing-up time (every state within 0.01 of upright, staying there), and ends up
    when the final state is within the robustness board's tolerance. *friction*: the files'
    ``FRICTION`` setting (``on``: the motor's joint's friction cancelled, ``off``: not; None:
    the file's own). A file that checks its design on its own model of the rig says which of
    its back-off settings it kept (``{}``: its own)."""
    import importlib.util

    from double_pendulum.analysis.leaderboard import get_swingup_time
    from double_pendulum.model.model_parameters import model_parameters
    from double_pendulum.model.symbolic_plant import SymbolicDoublePendulum
    from double_pendulum.simulation.simulation import Simulator

    os.environ.setdefault("MPLBACKEND", "Agg")
    rows = []
    for robot in robots:
        folder = benchmark / "leaderboard" / robot / "simulation_v2"
        sys.path.insert(0, str(folder))
        sys.modules.pop("sim_parameters", None)  # each board folder has its own
        cwd = os.getcwd()
        os.chdir(folder)  # the board's sim_parameters.py reads its rig relative to it
        try:
            spec = importlib.util.spec_from_file_location(f"con_{robot}",
                                                          EXAMPLES / f"con_{robot}.py")
            assert spec is not None and spec.loader is not None
            con = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(con)
        finally:
            os.chdir(cwd)
            sys.path.remove(str(folder))
        for (design, model) in RIGS:
            for variant in variants:
                mpar = model_parameters(model_design=design, model_id=model + variant,
                                        robot=robot)
                mpar.set_torque_limit([6.0, 0.0] if robot == "pendubot" else [0.0, 6.0])
                t0 = time.perf_counter()
                try:
                    controller = con.build(mpar, robot, **({} if friction is None
                                                           else {"friction": friction}))
                except Exception as exc:  # a plan that does not converge, a refused rig
                    rows.append((robot, design, model + variant, "not built", str(exc)[:60]))
                    print(*rows[-1], flush=True)
                    continue
                controller.init()
                sim = Simulator(plant=SymbolicDoublePendulum(model_pars=mpar))
                T, X, U = sim.simulate(t0=0.0, x0=[0.0, 0.0, 0.0, 0.0], tf=10.0, dt=0.002,
                                       controller=controller, integrator="runge_kutta")
                X = np.asarray(X)
                # The board's own criterion: the tip above 0.9 of the full height, staying.
                swing = get_swingup_time(T=np.asarray(T), X=X, has_to_stay=True, mpar=mpar,
                                         method="height", height=0.9, t_final=10.0)
                d = X[-1] - np.array([np.pi, 0.0, 0.0, 0.0])
                d[:2] = (d[:2] + np.pi) % (2 * np.pi) - np.pi
                up = bool(np.all(np.abs(d) < [0.35, 0.35, 1.0, 1.0]))
                rows.append((robot, design, model + variant,
                             f"swing-up {swing:.2f} s" if swing < 10.0 else "no swing-up",
                             f"final upright: {'yes' if up else 'no'} (angles within "
                             f"{np.max(np.abs(d[:2])):.3f} rad), peak torque "
                             f"{np.max(np.abs(U)):.1f} N m, {time.perf_counter() - t0:.0f} s"
                             + (f", kept {controller.back_off}" if hasattr(controller, "back_off")
                                else "")))
                print(*rows[-1], flush=True)
    print("\n| robot | design | model | board's criterion | |\n|---|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")


def policy_step() -> None:
    """The median and 90th percentile of a policy's step from Python."""
    import equilibrist

    for name, kind in (("acrobot", "lqr"), ("acrobot", "lqg"), ("cartpole", "lqr")):
        pi = equilibrist.policy(name, controller=kind, rate=200.0)
        y = np.array(pi.controller.x_op)[[pi.controller.state_names.index(o)
                                          for o in pi.outputs]] + 0.01
        times = []
        for k in range(20000):
            t0 = time.perf_counter()
            pi(k / 200.0, y)
            times.append(time.perf_counter() - t0)
        us = np.array(times[1000:]) * 1e6
        print(f"{name:9s} {kind:4s} step median {np.median(us):5.1f} us, 90 % "
              f"{np.percentile(us, 90):5.1f} us")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--benchmark", type=Path, help="where double_pendulum is unpacked")
    parser.add_argument("--board", choices=("simulation", "robustness"))
    parser.add_argument("--robot", choices=ROBOTS, action="append")
    parser.add_argument("--plant", action="store_true")
    parser.add_argument("--policy", action="store_true")
    parser.add_argument("--rigs", action="store_true",
                        help="the controller files on the other rigs of model_parameters")
    parser.add_argument("--variant", choices=VARIANTS, action="append")
    parser.add_argument("--friction", choices=("on", "off"),
                        help="with --rigs: the files' friction compensation (default: theirs)")
    args = parser.parse_args()
    if args.policy:
        policy_step()
    if args.plant or args.board or args.rigs:
        if args.benchmark is None:
            parser.error("--board, --plant and --rigs need --benchmark DIR")
        if args.rigs:
            rigs(args.benchmark, args.robot or list(ROBOTS), args.variant or list(VARIANTS),
                 args.friction)
        if args.plant:
            plant(args.benchmark)
        if args.board:
            for robot in args.robot or ROBOTS:
                board(args.benchmark, robot, args.board)


if __name__ == "__main__":
    main()
