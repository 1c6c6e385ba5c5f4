"""Plots and animations of real simulation results, the plot/animate commands on
saved files, and the main job (``equilibrist demo``) writing its report folder."""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from equilibrist.cli.main import main
from equilibrist.control import design
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import LQG, Noise, Pulse, simulate, simulate_batch
from equilibrist.viz.animation import animate_result
from equilibrist.viz.plots import plot_batch
from equilibrist.viz.plots_runs import plot_response
from equilibrist.viz.runs import as_run


@pytest.fixture(scope="module")
def cartpole_run():
    system = get_system("cartpole")
    d = design(system, rate=100.0)
    return simulate(system, LQG.from_design(d), duration=2.0, x0={"theta": 0.1},
                    noise=Noise.from_design(d), seed=3, events=[Pulse(time=1.0, value=50.0, duration=0.1)])


def test_a_simulation_result_reads_as_a_run(cartpole_run):
    run = as_run(cartpole_run)
    assert run.system.key == "cartpole"
    assert np.array_equal(run.x, cartpole_run.states)
    assert np.array_equal(run.u, cartpole_run.applied)
    assert np.array_equal(run.u_command, cartpole_run.commanded)
    assert np.array_equal(run.estimate, cartpole_run.estimates)
    assert run.output_names == ("x", "theta")
    assert run.events == ((1.0, "push +50 N"),)
    assert run.fell is False and run.label == "LQG, 100 Hz"
    assert np.array_equal(run.x_op, cartpole_run.x_op)  # the plots mark the controller's point


def test_result_plot_and_animation(cartpole_run, tmp_path):
    fig = plot_response(cartpole_run, tmp_path / "r.png", width=5, row_height=1.0, dpi=40)
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {"true", "estimate", "measured", "applied", "limits"} <= set(legend)
    path = animate_result(cartpole_run, tmp_path / "a.gif", fps=5, width=120, height=90)
    with Image.open(path) as im:
        assert im.size == (120, 90) and im.n_frames == 11
        im.seek(5)  # t = 1.0 s: the push is announced on the frame
        pushed = np.asarray(im.convert("RGB"))
        im.seek(0)
        calm = np.asarray(im.convert("RGB"))
    red = np.array([0xD1, 0x26, 0x3B])
    band = slice(int(0.1 * 90), int(0.3 * 90))  # the note's line, under the captions

    def reds(f):
        return int(np.all(np.abs(f[band].astype(int) - red) < 40, axis=2).sum())

    assert reds(pushed) > reds(calm) + 3


@pytest.mark.slow  # compiles the gyroscope's simulation core on a fresh machine
def test_a_system_without_input_animates_without_gauges(tmp_path):
    system = get_system("gyroscope", euler="xyz")
    result = simulate(system, None, duration=0.4, rate=50.0,
                      x0={"theta": 0.3, "psi_dot": 200.0})
    path = animate_result(result, tmp_path / "g.gif", fps=10, width=96, height=72)
    with Image.open(path) as im:
        assert im.n_frames == 5
    fig = plot_response(result)
    assert [ax.get_ylabel() for ax in fig.axes][:2] == ["theta [deg]", "theta_dot [deg/s]"]


def _cli(*argv: str) -> int:
    return main(list(argv))


def test_plot_and_animate_commands_on_saved_results(cartpole_run, tmp_path, capsys):
    saved = cartpole_run.save(tmp_path / "run.npz")
    other = simulate(get_system("cartpole"), LQG.from_design(design(get_system("cartpole"), rate=100.0)),
                     duration=2.0, x0={"theta": 0.05}).save(tmp_path / "other.npz")
    assert _cli("plot", str(saved)) == 0
    with Image.open(tmp_path / "run.png") as im:
        assert im.format == "PNG"
    assert _cli("plot", str(saved), str(other), "--out", str(tmp_path / "cmp.svg"),
                "--states", "theta") == 0
    assert (tmp_path / "cmp.svg").read_text().lstrip().startswith("<?xml")
    assert _cli("animate", str(saved), "--size", "96x72", "--fps", "4") == 0
    with Image.open(tmp_path / "run.gif") as im:
        assert im.size == (96, 72) and im.n_frames == 9
    capsys.readouterr()
    assert _cli("animate", str(saved), "--out", str(tmp_path / "run.avi")) == 2
    assert "unsupported format '.avi'" in capsys.readouterr().err
    assert _cli("plot", str(tmp_path / "missing.npz")) == 2
    assert "no result file" in capsys.readouterr().err
    (tmp_path / "junk.npz").write_text("not a result")
    assert _cli("plot", str(tmp_path / "junk.npz")) == 2
    assert "is not a saved result" in capsys.readouterr().err


@pytest.mark.slow  # compiles the parallel batch core on a fresh machine
def test_batch_plots(tmp_path, capsys):
    system = get_system("cartpole")
    lqg = LQG.from_design(design(system, rate=100.0))
    x0 = np.zeros((6, 4))
    x0[:, 1] = np.linspace(-0.3, 0.3, 6)
    x0[:, 3] = np.tile([-1.0, 1.0], 3)
    batch = simulate_batch(system, lqg, runs=6, x0=x0, duration=1.0, record=True)
    fan = plot_batch(batch, tmp_path / "fan.png")
    assert "6 runs" in fan._suptitle.get_text()
    saved = batch.save(tmp_path / "batch.npz")
    assert _cli("plot", str(saved)) == 0
    with Image.open(tmp_path / "batch.png") as im:
        assert im.format == "PNG"
    assert _cli("animate", str(saved)) == 2
    assert "is a batch" in capsys.readouterr().err


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.src: list[str] = []

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.src.append(dict(attrs)["src"])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cartpole", "gyroscope"])
def test_demo_of_one_system_writes_its_report(name, tmp_path, capsys):
    out = tmp_path / "report"
    assert _cli("demo", name, "--out", str(out), "--size", "160x120") == 0
    printed = capsys.readouterr().out
    assert "stayed up" in printed and "yes" in printed
    page = (out / "index.html").read_text()
    links = _Links()
    links.feed(page)
    assert links.src, "the report shows no image"
    for src in links.src:
        path = out / src
        assert path.exists(), src
        with Image.open(path) as im:
            if src.endswith(".gif"):
                assert im.size == (160, 120) and im.n_frames > 10
    assert "Equations of motion" in page and "http" not in page
    if name == "cartpole":
        # The constrained MPC's case against the clipped LQR, and both regions of attraction.
        assert "cartpole/mpc_track.png" in links.src and "cartpole/mpc_regions.png" in links.src
        assert "the clipped LQR left the region" in page and "the MPC stayed up" in page
    runs = sorted(Path(out).rglob("*.npz"))
    assert runs, "the demo keeps its runs for 'equilibrist plot'"


@pytest.mark.slow
def test_tour_in_parallel_keeps_the_catalogue_order(tmp_path):
    from equilibrist.apps.tour import run_tour

    # Two systems without a swing-up or a region of attraction in their tour (the cart-pole's
    # demo test covers those): what is tested here is the order of parallel results.
    systems = [get_system("wheeled_pendulum"), get_system("seesaw")]
    outcomes = run_tour(systems, tmp_path, size=(96, 72), fps=5, max_frames=20, jobs=2)
    assert [o.key for o in outcomes] == ["wheeled_pendulum", "seesaw"]
    assert all(o.stayed_up for o in outcomes)
    page = (tmp_path / "index.html").read_text()
    assert page.index('id="wheeled_pendulum"') < page.index('id="seesaw"')
    for o in outcomes:
        with Image.open(tmp_path / o.section.anchor / "animation.gif") as im:
            assert im.size == (96, 72) and im.n_frames == 20
