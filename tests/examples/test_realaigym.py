"""RealAIGym's controller files (examples/realaigym/): loaded as the benchmark loads them,
their controller exported to C and replayed bit for bit by ``make check``.

The benchmark's package is not installed here: its two names a file reads, the
controller interface and the board folder's ``mpar``, are stood in for by the smallest
objects that behave as the benchmark's do (``AbstractController.init`` calls ``init_``,
``get_control_output`` calls ``get_control_output_``; ``mpar`` holds the identified
design C.1, model 1.0 with the board's settings). Truth: the file's own controller stepped
from Python for the vectors the export replays in C (``make check``: 0 mismatches); and
from the board's start (hanging at rest) the torque is the shoulder's alone. The acrobot's
file on a rig it was not tuned on (design A.0, model 1.1 of ``double_pendulum``'s
identifications: a shorter, lighter second link), run by the adaptive integrator (not the
fixed-step one the file checks its design with) for the boards' 10 s from hanging: the final
state within the robustness board's tolerance, where the file's own settings unchecked fall.
"""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import equilibrist
from equilibrist.export.writer import export_controller
from equilibrist.sim import simulate
from equilibrist.systems.dfki_parameters import settings_of
from support.export import make_check

FOLDER = Path(__file__).resolve().parents[2] / "examples" / "realaigym"


class _Interface:
    """The benchmark's ``AbstractController``, as much of it as a controller file uses."""

    def init(self) -> None:
        self.init_()

    def get_control_output(self, x: np.ndarray, t: float | None = None) -> np.ndarray:
        return self.get_control_output_(x, t)


def _board_parameters(robot: str) -> types.SimpleNamespace:
    """The v2 boards' ``mpar``: design C.1, model 1.0 (its model_parameters.yml), rotors,
    damping and friction off, 6 N m on the actuated joint."""
    return types.SimpleNamespace(
        m=[0.5234602302310271, 0.6255677234174437], l=[0.2, 0.3],
        r=[0.2, 0.25569305436052964], I=[0.031887199591513114, 0.05086984812807257],
        b=[0.0, 0.0], cf=[0.0, 0.0], tl=[6.0, 0.0] if robot == "pendubot" else [0.0, 6.0],
        Ir=0.0, gr=6.0, g=9.81)


def _load(monkeypatch: pytest.MonkeyPatch, robot: str) -> types.ModuleType:
    """``con_<robot>.py`` loaded as the benchmark loads it, from the board's folder."""
    interface = types.ModuleType("double_pendulum.controller.abstract_controller")
    interface.AbstractController = _Interface  # type: ignore[attr-defined]
    board = types.ModuleType("sim_parameters")
    board.mpar = _board_parameters(robot)  # type: ignore[attr-defined]
    for name in ("double_pendulum", "double_pendulum.controller"):
        monkeypatch.setitem(sys.modules, name, types.ModuleType(name))
    monkeypatch.setitem(sys.modules, interface.__name__, interface)
    monkeypatch.setitem(sys.modules, "sim_parameters", board)
    spec = importlib.util.spec_from_file_location(f"con_{robot}", FOLDER / f"con_{robot}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def pendubot_file(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    return _load(monkeypatch, "pendubot")


def test_the_pendubot_file_exports_its_controller_with_make_check_exact(
        pendubot_file: types.ModuleType, tmp_path: Path) -> None:
    con = pendubot_file
    assert set(con.leaderboard_config) >= {"csv_path", "name", "simple_name", "username"}
    ctrl = con.controller.policy.controller
    # What the file builds: the tracker with its angles wrapped and its rates differenced.
    assert ctrl.settings["kind"] == "tvlqr" and ctrl.settings["wrap"] is True
    assert ctrl.settings["rates"] == "differenced"
    u = con.controller.get_control_output(np.zeros(4), 0.0)
    assert u[1] == 0.0 and u[0] != 0.0  # the shoulder's motor drives the pendubot
    system = equilibrist.get_system("dfki_double_pendulum",
                                    **settings_of(_board_parameters("pendubot"),
                                                  robot="pendubot"))
    out = tmp_path / "pendubot"
    report = export_controller(ctrl, out, system=system, duration=0.5)
    assert report is not None
    assert " 0 mismatches" in make_check(out)


def _upright_miss(x: np.ndarray) -> np.ndarray:
    miss = np.asarray(x, dtype=float) - np.array([np.pi, 0.0, 0.0, 0.0])
    miss[:2] = (miss[:2] + np.pi) % (2 * np.pi) - np.pi
    return np.abs(miss)


@pytest.mark.slow
def test_the_acrobot_file_swings_up_a_rig_it_was_not_tuned_on(
        monkeypatch: pytest.MonkeyPatch) -> None:
    con = _load(monkeypatch, "acrobot")
    # double_pendulum's model_parameters(model_design="design_A.0", model_id="model_1.1").
    a0 = types.SimpleNamespace(m=[0.608, 0.63], l=[0.3, 0.2], r=[0.275, 0.166],
                               I=[0.05472, 0.02522], b=[0.0, 0.0], cf=[0.0, 0.0],
                               tl=[0.0, 6.0], Ir=0.0, gr=6.0, g=9.81)
    system = equilibrist.get_system("dfki_double_pendulum", **settings_of(a0, robot="acrobot"))
    tolerance = np.array([0.35, 0.35, 1.0, 1.0])  # the robustness board's, of the final state
    for check, upright in (("on", True), ("off", False)):
        ctrl = con.build(a0, "acrobot", check=check).policy.controller
        run = simulate(system, ctrl, duration=10.0, x0=np.zeros(4), region={},
                       integrator="adaptive")
        assert bool(np.all(_upright_miss(run.final_state) < tolerance)) is upright, check
