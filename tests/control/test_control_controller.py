"""The controller contract: the linear form against the textbook equations, the registry,
the Python protocol and the checks of a nonlinear controller's source."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.control.controller import as_python_controller
from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController, check_source
from equilibrist.control.python_controller import PythonController, StepAdapter
from equilibrist.controllers.kinds import ControllerRequest, build_controller, register_controller
from equilibrist.errors import ControllerError
from equilibrist.native.linear_layout import LINEAR_BLOCKS, LINEAR_HEADER
from equilibrist.numeric.lookup import get_system


@pytest.fixture(scope="module")
def cartpole_designs():
    system = get_system("cartpole")
    return {form: design(system, rate=200.0, kalman_form=form) for form in ("current", "predictor")}


def textbook_lqg(d, ys, rs, tracking):
    """The discrete LQG of the design's docstring, written out with numpy."""
    plant, disc = d.plant, d.discrete
    C = disc.C
    z = np.zeros(plant.n_states)
    us, xs = [], []
    kc = d.Kc if tracking else np.zeros((plant.n_inputs, 0))
    r0 = plant.x0[[plant.state_names.index(t) for t in d.tracked]] if tracking else np.zeros(0)
    for y, r in zip(ys, rs, strict=True):
        dy = y - C @ plant.x0
        xhat = z + d.Kf @ (dy - C @ z) if d.kalman_form == "current" else z
        u = plant.u0 - d.K @ xhat + kc @ (r - r0)
        # the command acts as computed (no saturation here)
        if d.kalman_form == "current":
            z = disc.A @ xhat + disc.B @ (u - plant.u0)
        else:
            z = disc.A @ z + disc.B @ (u - plant.u0) + d.Kf @ (dy - C @ z)
        us.append(u)
        xs.append(plant.x0 + xhat)
    return np.array(us), np.array(xs)


@pytest.mark.parametrize("form", ["current", "predictor"])
@pytest.mark.parametrize("tracking", [False, True])
def test_lqg_form_is_the_textbook_lqg(cartpole_designs, form, tracking):
    d = cartpole_designs[form]
    ctrl = LinearController.from_design(d, kind="lqg", tracking=tracking)
    assert ctrl.form == form and ctrl.n_z == 4 and ctrl.rate == 200.0
    rng = np.random.default_rng(1)
    ys = ctrl.y_op + 0.05 * rng.standard_normal((60, ctrl.n_outputs))
    rs = ctrl.r_op + 0.1 * rng.standard_normal((60, ctrl.n_references))
    want_u, want_x = textbook_lqg(d, ys, rs if tracking else np.zeros((60, 0)), tracking)
    z = ctrl.z0
    for k, (y, r) in enumerate(zip(ys, rs, strict=True)):
        u = ctrl.output(z, y, r)
        np.testing.assert_allclose(u, want_u[k], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(ctrl.estimate(z, y), want_x[k], rtol=1e-10, atol=1e-12)
        z = ctrl.update(z, y, r, u)


def test_state_feedback_form_is_minus_k():
    d = design(get_system("cartpole"), rate=100.0)
    ctrl = LinearController.from_design(d, kind="lqr")
    assert ctrl.n_z == 0 and ctrl.output_names == d.plant.state_names
    x = d.plant.x0 + np.array([0.1, -0.05, 0.2, 0.0])
    np.testing.assert_allclose(ctrl.output(ctrl.z0, x), d.plant.u0 - d.K @ (x - d.plant.x0),
                               rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(ctrl.estimate(ctrl.z0, x), x)
    np.testing.assert_array_equal(ctrl.u_min, [d.params["F_min"]])
    np.testing.assert_array_equal(ctrl.u_max, [d.params["F_max"]])


def test_packed_layout_puts_each_block_at_its_offset(cartpole_designs):
    ctrl = LinearController.from_design(cartpole_designs["current"], kind="lqg", tracking=True)
    p = ctrl.packed()
    for name, _dims in LINEAR_BLOCKS:
        block = np.asarray(getattr(ctrl, name)).reshape(-1)
        start = int(p[LINEAR_HEADER.index(name)])
        np.testing.assert_array_equal(p[start : start + block.size], block)
    assert p.size == len(LINEAR_HEADER) + sum(np.size(getattr(ctrl, n)) for n, _ in LINEAR_BLOCKS)


def test_a_controller_started_at_an_estimate(cartpole_designs):
    ctrl = LinearController.from_design(cartpole_designs["predictor"], kind="lqg")
    x = ctrl.x_op + np.array([0.01, 0.02, 0.0, 0.0])
    moved = ctrl.start_at(x)
    np.testing.assert_allclose(moved.estimate(moved.z0, moved.y_op + moved.z0[[0, 1]]), x)


def test_lqg_needs_a_rate_and_bad_shapes_are_named():
    d = design(get_system("cartpole"))
    with pytest.raises(ControllerError, match="sample rate"):
        LinearController.from_design(d, kind="lqg")
    with pytest.raises(ControllerError, match="expected 'lqr' or 'lqg'"):
        LinearController.from_design(d, kind="pid")
    with pytest.raises(ValueError, match="K has shape"):
        LinearController.state_feedback(np.ones((2, 3)), x_op=np.zeros(4), u_op=np.zeros(1))


def test_registry_builds_lqr_lqg_none_and_refuses_unknown_names():
    req = ControllerRequest(system=get_system("cartpole"), rate=100.0)
    assert build_controller("lqr", req).kind == "lqr"
    assert build_controller("lqg", req).kind == "lqg"
    assert build_controller("none", req) is None
    with pytest.raises(ControllerError, match=r"'zigzag' is unknown for cartpole"):
        build_controller("zigzag", req)

    @register_controller("test-hold")
    def _hold(request):
        raise ControllerError(f"test-hold does not apply to {request.system.key}")

    try:
        with pytest.raises(ControllerError, match="does not apply to cartpole"):
            build_controller("test-hold", req)
    finally:  # a kind registered in this process is offered everywhere: take it back
        from equilibrist.controllers.kinds import names, unregister

        unregister("test-hold")
    assert "test-hold" not in names()


def test_design_at_another_operating_point():
    system = get_system("cartpole")
    d = design(system, rate=100.0, at={"theta": np.pi})
    assert d.plant.x0[system.state_names.index("theta")] == pytest.approx(np.pi)
    # hanging: the open loop is stable, the closed loop too
    assert np.all(np.abs(np.linalg.eigvals(d.discrete.A - d.discrete.B @ d.K)) < 1)


SOURCE = '''
import math


def output(t, z, y, r, params, u_out):
    u_out[0] = params[0] * math.sin(y[1]) + z[0]


def update(t, z, y, r, u_applied, params, z_out):
    z_out[0] = z[0] + params[1]
'''


def test_nonlinear_source_runs_in_python_and_is_checked():
    system = get_system("cartpole")
    eq = system.operating_point()
    ctrl = NonlinearController(
        name="demo", source=SOURCE, params=[2.0, 0.5], z0=[0.0], rate=100.0, x_op=eq.x,
        u_op=eq.u, state_names=system.state_names, input_names=system.input_names,
        output_names=("x", "theta"),
    )
    rt = ctrl.runtime()
    assert isinstance(rt, PythonController)
    u0 = rt.output(0.0, np.array([0.0, 0.3]), np.zeros(0))
    assert u0[0] == pytest.approx(2.0 * np.sin(0.3))
    rt.update(0.0, np.array([0.0, 0.3]), np.zeros(0), u0)
    assert rt.output(0.01, np.array([0.0, 0.3]), np.zeros(0))[0] == pytest.approx(2.0 * np.sin(0.3) + 0.5)
    with pytest.raises(ControllerError, match="no function update"):
        check_source("def output(t, z, y, r, params, u_out):\n    pass\n", has_estimate=False)
    with pytest.raises(ControllerError, match="only math and numpy"):
        check_source("import os\n" + SOURCE, has_estimate=False)
    with pytest.raises(ControllerError, match="reserved"):
        check_source(SOURCE + "\ndef linear_output(t):\n    pass\n", has_estimate=False)
    with pytest.raises(ControllerError, match="does not parse"):
        check_source("def output(:\n", has_estimate=False)


def test_step_functions_run_through_the_adapter():
    seen = []

    class Old:
        rate = 50.0
        outputs = ("x",)

        def __init__(self):
            self.estimate = np.zeros(4)

        def step(self, t, y, r):
            return [1.0]

        def applied(self, u):
            seen.append(float(u[0]))

    adapted = as_python_controller(Old())
    assert isinstance(adapted, StepAdapter) and adapted.rate == 50.0 and adapted.outputs == ("x",)
    assert adapted.output(0.0, np.zeros(1), np.zeros(0))[0] == 1.0
    adapted.update(0.0, np.zeros(1), np.zeros(0), np.array([0.5]))
    assert seen == [0.5]
    np.testing.assert_array_equal(adapted.estimate, np.zeros(4))
    fn = as_python_controller(lambda t, y, r: [2.0])
    assert fn.rate is None and fn.output(0.0, np.zeros(1), np.zeros(0))[0] == 2.0
    with pytest.raises(ControllerError, match="is not a controller"):
        as_python_controller(3)


def test_python_controller_names_what_the_user_wrote():
    from equilibrist.control.controller import as_python_controller, python_controller_name
    from equilibrist.control.python_controller import PythonControllerBase

    def hold(t, y, r):
        return np.zeros(1)

    class Mine(PythonControllerBase):
        def output(self, t, y, r):
            return np.zeros(1)

    class Stepper:
        def step(self, t, y, r):
            return np.zeros(1)

    assert python_controller_name(as_python_controller(hold)) == "hold"
    assert python_controller_name(as_python_controller(Mine())) == "Mine"
    assert python_controller_name(as_python_controller(Stepper())) == "Stepper"
