"""The export takes a controller value and chooses its exporter by the value's type, with no
kind name: a hand-built linear controller exports (as the linear library on its packed vector,
``make check`` bit for bit), a design's LQR/LQG as the design's library, a design's controller
changed after as the value it is, and a type of one's own with the exporter it registers."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.control.design_record import Design
from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.errors import ExportError
from equilibrist.export import writer
from equilibrist.numeric.system import System
from equilibrist.sim.run import simulate
from support.export import make_check


@pytest.fixture(scope="module")
def cart() -> tuple[System, Design]:
    system = get_system("cartpole")
    return system, design(system, rate=200.0)


def _hand_built(d: Design) -> LinearController:
    """The design's LQG assembled from its matrices by hand: no design attached."""
    plant = d.plant
    return LinearController.lqg(
        d.K, Ad=d.discrete.A, Bd=d.discrete.B, Kf=d.Kf,
        outputs=plant.output_names, x_op=plant.x0, u_op=plant.u0, rate=200.0,
        form=d.kalman_form, state_names=plant.state_names,
        input_names=plant.input_names, u_min=[-30.0], u_max=[30.0])


def test_as_nonlinear_runs_to_the_bit_as_the_linear_controller(cart: tuple[System, Design]) -> None:
    system, d = cart
    lin = _hand_built(d)
    nonlinear = lin.as_nonlinear()
    assert isinstance(nonlinear, NonlinearController) and nonlinear.has_estimate
    a = simulate(system, lin, duration=3.0, x0={"theta": 0.1}, seed=4)
    b = simulate(system, nonlinear, duration=3.0, x0={"theta": 0.1}, seed=4)
    assert np.array_equal(a.states, b.states) and np.array_equal(a.applied, b.applied)
    assert np.abs(a.states[-1, 1]) < 0.01  # it balances: a run that means something
    # Without a rate there is no digital controller to write.
    gain = LinearController.state_feedback(d.K, x_op=np.zeros(4), u_op=[0.0])
    with pytest.raises(Exception, match="has no rate"):
        gain.as_nonlinear()


def test_a_hand_built_linear_controller_exports_and_checks_bit_for_bit(
        cart: tuple[System, Design], tmp_path: Path) -> None:
    system, d = cart
    lin = _hand_built(d)
    assert writer.exporter_of(lin) is writer._export_linear
    report = writer.export_controller(lin, tmp_path / "hand", system=system)
    assert (tmp_path / "hand" / "lqg.c").exists() and "hil_host.c" in report.files
    assert " 0 mismatches" in make_check(tmp_path / "hand")


def test_a_design_controller_is_the_design_library_until_it_is_changed(
        cart: tuple[System, Design], tmp_path: Path) -> None:
    system, d = cart
    as_made = LinearController.from_design(d, kind="lqg")
    writer.export_controller(as_made, tmp_path / "design", system=system)
    assert (tmp_path / "design" / "cartpole_lqg.h").exists()  # the design's documented library
    moved = as_made.start_at(np.array([0.1, 0.05, 0.0, 0.0]))  # started elsewhere: another value
    assert not writer.made_by_design(moved) and writer.made_by_design(as_made)
    writer.export_controller(moved, tmp_path / "moved", system=system)
    assert not (tmp_path / "moved" / "cartpole_lqg.h").exists()
    assert " 0 mismatches" in make_check(tmp_path / "moved")


def test_the_exporter_follows_the_type(cart: tuple[System, Design]) -> None:
    system, d = cart
    from equilibrist.control.mpc import mpc
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.control.swingup import SwingUpController, swingup

    sw = swingup(system, design=d)
    assert isinstance(sw, SwingUpController)
    rt = mpc(system, design=d, horizon=5).runtime()
    assert isinstance(rt, MPCRuntime)
    chosen = {type(v).__name__: writer.exporter_of(v).__name__
              for v in (sw, rt, sw.__class__.__mro__[1](**{  # a plain NonlinearController
                  f.name: getattr(sw, f.name) for f in fields(sw)}))}
    # The swing-up is a NonlinearController: the generic library, with no time in its API.
    assert chosen == {"SwingUpController": "nonlinear", "MPCRuntime": "mpc",
                      "NonlinearController": "nonlinear"}

    class Mine(NonlinearController):
        pass

    def mine_exporter(*args: object, **kwargs: object) -> None:
        raise AssertionError("not called here")

    try:
        writer.register_exporter(Mine)(mine_exporter)
        value = Mine(**{f.name: getattr(sw, f.name) for f in fields(sw)})
        assert writer.exporter_of(value) is mine_exporter
    finally:
        writer.EXPORTERS.pop(Mine, None)
    with pytest.raises(ExportError, match="open loop"):
        writer.exporter_of(None)
    with pytest.raises(ExportError, match="a dict has no C export"):
        writer.exporter_of({})


def test_a_type_that_is_handed_no_time_refuses_a_source_that_reads_it(
        cart: tuple[System, Design]) -> None:
    """The swing-up's C API takes no time (its law never reads it): a swing-up whose source
    reads ``t`` would be handed 0 there, and is refused in one line."""
    from equilibrist.control.swingup import SwingUpController, swingup
    from equilibrist.errors import ControllerError

    system, d = cart
    sw = swingup(system, design=d)
    head = "def output(t, z, y, r, p, u_out):\n"
    assert head in sw.source
    values = {f.name: getattr(sw, f.name) for f in fields(sw)}
    values["source"] = sw.source.replace(head, head + "    late = t + 0.0\n", 1)
    with pytest.raises(ControllerError, match="reads the time t, which a SwingUpController"):
        SwingUpController(**values)
    NonlinearController(**values)  # a plain one is handed the time: accepted
