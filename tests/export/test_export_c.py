"""The generated C library, compiled and run: its constants, its step, its strictness.

Generated code is never compared as text: it is compiled with the export's
strict flags and its numbers are compared with the design's and with an
independent numpy transcription of the documented equations.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.errors import ExportError
from equilibrist.export.data import controller_data
from equilibrist.export.vectors import compile_controller
from equilibrist.native import c_programs, c_text, linear_library
from equilibrist.native.shared_library import STRICT_FLAGS, compiler
from equilibrist.numeric.lookup import get_system
from support import require
from support.export import measurements, reference_run

SYSTEMS = ("cartpole", "reaction_wheel_pendulum", "wheeled_pendulum", "ball_beam", "seesaw")


@pytest.fixture(scope="module")
def designs():
    out = {}
    for name in SYSTEMS:
        system = get_system(name)
        out[name, "current"] = design(system, rate=100)
    out["cartpole", "predictor"] = design(get_system("cartpole"), rate=200, kalman_form="predictor")
    out["seesaw", "predictor"] = design(get_system("seesaw"), rate=100, kalman_form="predictor")
    return out


CASES = [(name, "current", "lqg") for name in SYSTEMS] + [
    ("cartpole", "predictor", "lqg"),
    ("seesaw", "predictor", "lqg"),
    ("cartpole", "current", "lqr"),
    ("ball_beam", "current", "lqr"),
]


@pytest.mark.parametrize(("name", "form", "controller"), CASES)
def test_step_matches_the_documented_equations(designs, name, form, controller) -> None:
    d = designs[name, form]
    ys, rs = None, None
    for precision in ("double", "float"):
        with compile_controller(d, controller=controller, precision=precision) as c:
            data = c.data
            if ys is None:
                ys, rs = measurements(data, 400, seed=3)
            expected_u, expected_x = reference_run(data, ys, rs)
            got_u = np.array([c.step(y, r) for y, r in zip(ys, rs, strict=True)])
            scale = np.max(np.abs(expected_u - data.u0), axis=0) + 1e-3 * (data.u_max - data.u_min)
            err = np.max(np.abs(got_u - expected_u), axis=0)
            if precision == "double":
                assert np.all(err <= 1e-12 * scale), (name, controller, err)
                assert np.allclose(c.estimate(), expected_x[-1], rtol=1e-12, atol=1e-12)
            else:
                assert np.all(err <= 1e-4 * scale), (name, controller, err)
            # The run must have saturated now and then, and moved the input.
            assert np.ptp(expected_u) > 0


def test_saturation_is_counted_and_applied(designs) -> None:
    with compile_controller(designs["cartpole", "current"], controller="lqr") as c:
        data = c.data
        far = data.x0.copy()
        far[data.state_names.index("theta")] = 1.0  # a push far beyond the 200 N limit
        u = c.step(far)
        assert c.saturated == 1
        assert u[0] in (data.u_min[0], data.u_max[0])
        u = c.step(data.x0)
        assert c.saturated == 0 and u[0] == pytest.approx(data.u0[0])


def test_init_at_starts_from_the_given_estimate(designs) -> None:
    d = designs["reaction_wheel_pendulum", "current"]
    with compile_controller(d) as c:
        data = c.data
        x_start = data.x0 + 0.01 * np.arange(1, data.n_states + 1)
        c.reset(x_start)
        y = data.y0.copy()
        c.step(y)
        # current form: xhat = z + Kf (dy - C z) with z = x_start - x0
        z = x_start - data.x0
        assert np.allclose(c.estimate(), data.x0 + z + data.Kf @ (-data.C @ z), atol=1e-14)
        c.reset()
        c.step(y)
        assert np.allclose(c.estimate(), data.x0, atol=0)
        with pytest.raises(ExportError, match="expected"):
            c.reset([1.0])


PRINT_CONSTANTS = r"""
#include <stdio.h>
#include "{name}.h"
#define P(label, arr, count) do {{ int i_; printf("%s", label); \
    for (i_ = 0; i_ < (count); ++i_) printf(" %.17g", (double)((const {name}_real *)(arr))[i_]); \
    printf("\n"); }} while (0)
int main(void)
{{
    P("X0", {name}_X0, {N}_N_STATES);
    P("U0", {name}_U0, {N}_N_INPUTS);
    P("Y0", {name}_Y0, {N}_N_MEASUREMENTS);
    P("U_MIN", {name}_U_MIN, {N}_N_INPUTS);
    P("U_MAX", {name}_U_MAX, {N}_N_INPUTS);
    P("AD", {name}_AD, {N}_N_STATES * {N}_N_STATES);
    P("BD", {name}_BD, {N}_N_STATES * {N}_N_INPUTS);
    P("C", {name}_C, {N}_N_MEASUREMENTS * {N}_N_STATES);
    P("K", {name}_K, {N}_N_INPUTS * {N}_N_STATES);
    P("KF", {name}_KF, {N}_N_STATES * {N}_N_MEASUREMENTS);
    P("KC", {name}_KC, {N}_N_INPUTS * {N}_N_REFERENCES);
    P("R0", {name}_R0, {N}_N_REFERENCES);
    printf("DT %.17g\n", {N}_SAMPLE_PERIOD);
    printf("RATE %.17g\n", {N}_SAMPLE_RATE);
    printf("PERIOD_US %lu\n", {N}_SAMPLE_PERIOD_US);
    printf("SIZES %d %d %d %d\n", {N}_N_STATES, {N}_N_INPUTS, {N}_N_MEASUREMENTS, {N}_N_REFERENCES);
    printf("ID %s\n", {N}_DESIGN_ID);
    printf("VERSION %s\n", {name}_version());
    return 0;
}}
"""


def _build(folder: Path, files: dict[str, str], sources: list[str], exe: str) -> Path:
    for rel, text in files.items():
        (folder / rel).write_text(text)
    out = folder / exe
    cmd = [*compiler(), *STRICT_FLAGS, "-O1", *(str(folder / s) for s in sources), "-o", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.mark.parametrize("precision", ["double", "float"])
def test_named_constants_are_the_designs_numbers(designs, tmp_path, precision) -> None:
    d = designs["ball_beam", "current"]
    data = controller_data(d)
    name, N = data.name, data.name.upper()
    files = {
        f"{name}.h": linear_library.header(data, precision=precision, version="test"),
        f"{name}.c": linear_library.source(data, precision=precision, version="test"),
        "show.c": PRINT_CONSTANTS.format(name=name, N=N),
    }
    exe = _build(tmp_path, files, [f"{name}.c", "show.c"], "show")
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    rows = {}
    for line in out.splitlines():
        label, _, rest = line.partition(" ")
        rows[label] = rest
    def nums(label):
        return np.array([float(v) for v in rows[label].split()])
    rtol = 0 if precision == "double" else 1e-7
    expected = {
        "X0": d.plant.x0, "U0": d.plant.u0, "Y0": d.discrete.C @ d.plant.x0,
        "AD": d.discrete.A, "BD": d.discrete.B, "C": d.discrete.C, "K": d.K, "KF": d.Kf,
        "KC": d.Kc, "R0": d.r0,
    }
    for label, value in expected.items():
        assert np.allclose(nums(label), np.ravel(value), rtol=rtol, atol=0), label
    low, high = get_system("ball_beam").input_limits
    assert np.array_equal(nums("U_MIN"), low) and np.array_equal(nums("U_MAX"), high)
    assert float(rows["DT"]) == d.dt and float(rows["RATE"]) == d.rate
    assert int(rows["PERIOD_US"]) == 10000
    assert rows["SIZES"] == "4 1 2 1"
    assert rows["ID"] == data.fingerprint
    assert data.fingerprint in rows["VERSION"] and f"precision={precision}" in rows["VERSION"]


def test_the_library_needs_no_library(designs, tmp_path) -> None:
    """No symbol of the object file is left for a library to define (no libm, no libc)."""
    for controller in ("lqg", "lqr"):
        data = controller_data(designs["wheeled_pendulum", "current"], controller=controller)
        (tmp_path / f"{data.name}.h").write_text(linear_library.header(data, precision="float", version="t"))
        (tmp_path / f"{data.name}.c").write_text(linear_library.source(data, precision="float", version="t"))
        obj = tmp_path / f"{data.name}.o"
        subprocess.run([*compiler(), *STRICT_FLAGS, "-O2", "-c", str(tmp_path / f"{data.name}.c"),
                        "-o", str(obj)], check=True)
        undefined = subprocess.run(["nm", "-u", str(obj)], capture_output=True, text=True,
                                   check=True).stdout.split()
        assert undefined == [], undefined


def test_literals_read_back_exactly() -> None:
    values = [0.1, -1e-300, 1.0, 123456789.0, 2.0 ** -30, -0.0, 1 / 3]
    for v in values:
        assert float(c_text.literal(v, "double")) == v
        text = c_text.literal(v, "float")
        assert text.endswith("f") and np.float32(float(text[:-1])) == np.float32(v)
    with pytest.raises(ExportError):
        c_text.literal(float("inf"), "double")
    with pytest.raises(ExportError):
        c_text.literal(1e300, "float")


def test_a_continuous_design_or_no_input_is_refused() -> None:
    with pytest.raises(ExportError, match="sample rate"):
        controller_data(design(get_system("cartpole")))
    with pytest.raises(ExportError, match="controller 'pid' is unknown"):
        controller_data(design(get_system("cartpole"), rate=50), controller="pid")


def test_arduino_sketch_compiles_as_cpp(designs, tmp_path) -> None:
    """The sketch against a stand-in of the Arduino core, compiled as the IDE would (C++)."""
    cxx = require("g++", "c++")
    data = controller_data(designs["seesaw", "current"])
    (tmp_path / f"{data.name}.h").write_text(linear_library.header(data, precision="float", version="t"))
    (tmp_path / f"{data.name}.c").write_text(linear_library.source(data, precision="float", version="t"))
    (tmp_path / "sketch.cpp").write_text(c_programs.arduino_sketch(data, precision="float"))
    (tmp_path / "Arduino.h").write_text(
        "struct SerialStub { void begin(long) {} void println(const char *) {} };\n"
        "static SerialStub Serial;\n"
        "static unsigned long fake_us = 0;\n"
        "static unsigned long micros() { return fake_us += 1000; }\n"
    )
    (tmp_path / "main.cpp").write_text(
        '#include "Arduino.h"\n#include "sketch.cpp"\n'
        "int main() { setup(); for (int i = 0; i < 100; ++i) loop(); return 0; }\n"
    )
    subprocess.run([*compiler(), *STRICT_FLAGS, "-c", str(tmp_path / f"{data.name}.c"), "-o",
                    str(tmp_path / "lib.o")], check=True)
    proc = subprocess.run(
        [cxx, "-std=c++11", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wno-unused-function",
         f"-I{tmp_path}", str(tmp_path / "main.cpp"), str(tmp_path / "lib.o"), "-o",
         str(tmp_path / "sketch")],
        capture_output=True, text=True, check=False,
    )
    assert proc.returncode == 0, proc.stderr
    subprocess.run([str(tmp_path / "sketch")], check=True)
