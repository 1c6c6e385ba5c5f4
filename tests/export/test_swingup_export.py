"""The exported C swing-up: exact against the Python controller, `make check`, and in the loop."""

from __future__ import annotations

import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.control.swingup import SwingUpRuntime, swingup
from equilibrist.export.nonlinear_c import export_files, recorded_vectors
from equilibrist.native.nonlinear_library import CompiledNonlinear, nonlinear_files
from equilibrist.numeric.system import System
from equilibrist.sim.run import simulate
from equilibrist.tasks import get_task
from support.export import make_check

#: The C library functions the exported swing-up calls (its sine and cosine are the project's
#: own, written into the library: the same bits on every CPU).
MATH_FUNCTIONS = ("fabs", "floor")


@pytest.mark.parametrize(("name", "balance", "form"), [
    ("cartpole", "lqr", "current"), ("acrobot", "lqr", "current"), ("furuta", "lqr", "current"),
    ("reaction_wheel_pendulum", "lqr", "current"), ("cartpole", "lqg", "current"),
    ("reaction_wheel_pendulum", "lqg", "predictor"), ("furuta", "lqg", "current"),
])
def test_c_commands_equal_python_exactly(name: str, balance: str, form: str) -> None:
    """On recorded vectors (noisy swing-up), every C command is the Python one, bit for bit
    (and its estimate; with the LQG hand-over, the filter's state too)."""
    from equilibrist.control.design import design
    from equilibrist.control.swingup_law import Z

    system = get_system(name)
    d = design(system, rate=system.spec.control_rate, kalman_form=form)
    ctrl = swingup(system, design=d, balance=balance)
    vec = recorded_vectors(ctrl, system, duration=3.0, seed=2)
    py = SwingUpRuntime(ctrl, compiled=False)
    c = CompiledNonlinear(ctrl)
    try:
        for y, ua, u in zip(vec["y"], vec["u_applied"], vec["u"], strict=True):
            a = py.output(0.0, y, np.zeros(0))
            b = c.output(0.0, y, np.zeros(0))
            assert a[0] == b[0] == u[0]
            np.testing.assert_array_equal(py.estimate, c.estimate)
            py.update(0.0, y, np.zeros(0), ua)
            c.update(0.0, y, np.zeros(0), ua)
            np.testing.assert_array_equal(py.z, c._z)
        assert py.mode == "balance" or name == "acrobot"
        if balance == "lqg":
            assert np.any(py.z[Z["kz"]:Z["kz"] + 4] != 0.0), "the filter must have run"
    finally:
        c.close()


def test_make_check_in_the_exported_folder(tmp_path: Path) -> None:
    system = get_system("cartpole")
    folder = export_files(swingup(system), tmp_path / "out", system=system).folder
    assert " 0 mismatches" in make_check(folder)


def _undefined_symbols(source: Path) -> set[str]:
    """The symbols an object of *source* leaves for a library to define, by ``nm -u``.

    Compiled with ``-fno-builtin``: every call to a C library function stays a call (GCC would
    otherwise inline ``fabs``, and is free to inline others), so what the compiler sees called,
    under any spelling (a macro, ``(sin)(x)``, ``__builtin_sin``), is listed here."""
    obj = source.with_suffix(".o")
    subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2",
                    "-fno-builtin", "-c", str(source), "-o", str(obj)], check=True)
    nm = subprocess.run(["nm", "-u", str(obj)], capture_output=True, text=True, check=True)
    return {line.split()[-1] for line in nm.stdout.splitlines() if line.strip()}


def test_needs_only_the_stated_math_functions(tmp_path: Path) -> None:
    """The compiled swing-up calls fabs and floor from the C library and nothing else: no
    CPU-dispatched sine or cosine (its own are in the library), no libc; its header says so."""
    from equilibrist.native.nonlinear_library import math_functions

    files = nonlinear_files(swingup(get_system("cartpole")))
    for fname, text in files.items():
        (tmp_path / fname).write_text(text)
    assert _undefined_symbols(tmp_path / "swingup.c") == set(MATH_FUNCTIONS)
    # The export's own reckoning (the header's note, the Makefile's -lm) agrees with the compiler.
    assert math_functions(files["swingup.c"]) == MATH_FUNCTIONS
    assert f"Needs {', '.join(MATH_FUNCTIONS)} from <math.h> (-lm)." in files["swingup.h"]


def test_exported_code_closes_the_loop() -> None:
    """The C library swings the cart-pole up on the nonlinear plant, on its track."""
    system = get_system("cartpole")
    ctrl = swingup(system)
    task = get_task(system, "swingup")
    c = CompiledNonlinear(ctrl)
    try:
        res = simulate(system, c, duration=6.0, x0=task.draw_initial(np.random.default_rng(5)),
                       region=task.region)
    finally:
        c.close()
    assert not res.fell
    assert abs(math.remainder(res.final_state[1], 2 * math.pi)) < 0.02


def test_command_line_export_and_refusal(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # main() in this process: what is tested is what the command writes and refuses (the
    # console script's exit status in a process of its own is test_cli_core's).
    out = tmp_path / "cart"
    code = main(["export", "cartpole", "--controller", "swingup", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    assert " 0 mismatches" in make_check(out)
    capsys.readouterr()
    code = main(["export", "ball_beam", "--controller", "swingup", "--out", str(tmp_path / "bb")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.strip().count("\n") == 0 and "no swing-up" in err
    assert not (tmp_path / "bb").exists()


def test_command_line_lqg_hand_over(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--balance lqg`` reaches the builder: the exported library balances with the LQG."""
    out = tmp_path / "furuta"
    code = main(["export", "furuta", "--controller", "swingup", "--balance", "lqg", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    assert "balanced by the LQG" in (out / "swingup.h").read_text()
    assert " 0 mismatches" in make_check(out)
    assert main(["export", "furuta", "--controller", "swingup", "--balance", "pid",
                 "--out", str(tmp_path / "x")]) == 2
    assert not (tmp_path / "x").exists()


# -- the same translation for any NonlinearController ------------------------------------------
#: A hand-written controller of the cart-pole: filtered positions, finite-difference rates, a
#: state-feedback law on them with a reference for the cart, and a few of the translation's
#: rules (a tuple returned, a local only set, %, //, ** 2, min, max, abs, the time; not
#: ** 3: the translation multiplies as numba did, CPython calls pow, which may round otherwise).
DEMO_SOURCE = '''
N_OBS = 2


def clamp(v, lo, hi):
    return max(lo, min(v, hi))


def track(z, y, p, i):
    pos = z[i] + p[0] * (y[i] - z[i])
    rate = (pos - z[i]) * p[1]
    return pos, rate


def output(t, z, y, r, p, u_out):
    x, xd = track(z, y, p, 0)
    th, thd = track(z, y, p, 1)
    th = th - 2.0 * math.pi * math.floor((th + math.pi) / (2.0 * math.pi))
    wobble = 0.01 * math.sin(3.0 * t) + 0.001 * ((t * 7.0) % 1.3) - 1e-4 * (z[2] // 3.0)
    v = p[2] * (x - r[0]) + p[3] * th + p[4] * xd + p[5] * thd
    u_out[0] = clamp(-v + wobble, -p[6], p[6])


def update(t, z, y, r, u_applied, p, z_out):
    for i in range(N_OBS):
        pos, rate = track(z, y, p, i)
        z_out[i] = pos
    z_out[2] = z[2] + 1.0
    z_out[3] = abs(u_applied[0]) ** 2 / (1.0 + z[3])


def estimate(t, z, y, r, p, x_out):
    x, xd = track(z, y, p, 0)
    th, thd = track(z, y, p, 1)
    x_out[0] = x
    x_out[1] = th
    x_out[2] = xd
    x_out[3] = thd
'''


def _demo() -> tuple[System, NonlinearController]:
    from equilibrist.control.design import design

    system = get_system("cartpole")
    rate = float(system.spec.control_rate)
    K = np.asarray(design(system, rate=rate).K, dtype=float).reshape(-1)
    params = np.array([0.8, rate, K[0], K[1], K[2], K[3], 40.0])
    ctrl = NonlinearController(
        name="demo", source=DEMO_SOURCE, params=params, z0=np.array([0.0, 0.0, 0.0, 0.5]),
        rate=rate, x_op=np.zeros(4), u_op=np.zeros(1), state_names=system.state_names,
        input_names=system.input_names, output_names=("x", "theta"), tracked_names=("x",),
        has_estimate=True)
    return system, ctrl


def test_any_nonlinear_controller_exports_bit_for_bit() -> None:
    """A hand-written controller's export gives its Python runtime's commands, estimates and
    state, bit for bit, on recorded inputs (times, measurements, a reference step)."""

    system, ctrl = _demo()
    vec = recorded_vectors(ctrl, system, duration=2.0, seed=3)
    assert np.ptp(vec["r"][:, 0]) > 0, "the reference must step"
    py = ctrl.runtime()
    c = CompiledNonlinear(ctrl)
    try:
        for t, y, r, ua, u in zip(vec["t"][:, 0], vec["y"], vec["r"], vec["u_applied"], vec["u"],
                                  strict=True):
            a = py.output(t, y, r)
            b = c.output(t, y, r)
            np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(a, u)
            np.testing.assert_array_equal(py.estimate, c.estimate)
            py.update(t, y, r, ua)
            c.update(t, y, r, ua)
            np.testing.assert_array_equal(py.z, c._z)
        assert np.any(np.abs(vec["u"]) == 40.0) and np.any(np.abs(vec["u"]) < 40.0)
    finally:
        c.close()


def test_nonlinear_export_checks_and_fails_on_a_wrong_vector(tmp_path: Path) -> None:
    """``make check`` of the generic export passes, and fails once a recorded command is off
    by one unit in the last place; ``make hil-host`` builds the firmware around it."""

    system, ctrl = _demo()
    done = export_files(ctrl, tmp_path / "demo", system=system, duration=1.0)
    folder = done.folder
    assert (folder / "demo.h").exists() and "demo_estimate" in (folder / "demo.h").read_text()
    assert " 0 mismatches" in make_check(folder)
    hil = subprocess.run(["make", "hil-host"], cwd=folder, capture_output=True, text=True, check=False)
    assert hil.returncode == 0, hil.stderr
    text = (folder / "demo_vectors.h").read_text()
    head, rest = text.split("vec_u[", 1)
    first = rest.split("{", 2)[2].split("}", 1)[0]
    bumped = repr(float(np.nextafter(float(first), np.inf)))
    (folder / "demo_vectors.h").write_text(head + "vec_u[" + rest.replace(first, bumped, 1))
    bad = subprocess.run(["make", "check"], cwd=folder, capture_output=True, text=True, check=False)
    assert bad.returncode != 0 and "1 mismatches" in bad.stdout, bad.stdout


def test_two_exports_link_into_one_program(tmp_path: Path) -> None:
    """Every external symbol of an export carries its name: two swing-ups and the hand-written
    controller link into one program under the strict flags."""
    from equilibrist.native.nonlinear_library import math_functions

    system, demo = _demo()
    # The project's own cos (equilibrist.numeric.libm), its sin unused: still no warning.
    trig = NonlinearController(
        name="trig", source="def output(t, z, y, r, p, u_out):\n    u_out[0] = p[0] * eq_cos(y[1])\n"
        "\n\ndef update(t, z, y, r, u_applied, p, z_out):\n    return\n", params=np.ones(1),
        z0=np.zeros(0), rate=100.0, x_op=np.zeros(4), u_op=np.zeros(1),
        state_names=system.state_names, input_names=system.input_names,
        output_names=("x", "theta"))
    files = {**nonlinear_files(swingup(get_system("cartpole")), name="left"),
             **nonlinear_files(swingup(get_system("furuta"), balance="lqg"), name="right"),
             **nonlinear_files(demo), **nonlinear_files(trig)}
    assert math_functions(files["left.c"]) == tuple(sorted(MATH_FUNCTIONS))
    assert math_functions(files["right.c"]) == tuple(sorted(MATH_FUNCTIONS))
    assert "fabs" in math_functions(files["trig.c"])  # eq_cos's argument reduction
    for fname, text in files.items():
        (tmp_path / fname).write_text(text)
    (tmp_path / "main.c").write_text(
        '#include <stdio.h>\n#include "left.h"\n#include "right.h"\n#include "demo.h"\n#include "trig.h"\n'
        "int main(void)\n{\n    left_state a;\n    right_state b;\n    demo_state c;\n"
        "    trig_state d;\n    double y[2] = {0.0, 3.0}, r[1] = {0.0}, u[1];\n"
        "    left_init(&a);\n    right_init(&b);\n    demo_init(&c);\n    trig_init(&d);\n"
        "    left_output(&a, y, u);\n    right_output(&b, y, u);\n"
        "    demo_output(&c, 0.0, y, r, u);\n    trig_output(&d, 0.0, y, u);\n"
        '    printf("%.17g\\n", u[0]);\n'
        "    return u[0] != u[0];\n}\n")
    flags = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-ffp-contract=off"]
    libs = ("left", "right", "demo", "trig")
    for lib in libs:
        obj = tmp_path / f"{lib}.o"
        proc = subprocess.run(["cc", *flags, "-c", str(tmp_path / f"{lib}.c"), "-o", str(obj)],
                              capture_output=True, text=True, check=False)
        assert proc.returncode == 0, proc.stderr
        if shutil.which("nm"):
            nm = subprocess.run(["nm", "-g", "--defined-only", str(obj)], capture_output=True,
                                text=True, check=True)
            symbols = [line.split()[-1] for line in nm.stdout.splitlines() if line.strip()]
            assert symbols and all(s.startswith(f"{lib}_") for s in symbols), symbols
    proc = subprocess.run(["cc", *flags, "-I", str(tmp_path), *(str(tmp_path / f"{n}.o")
                                                               for n in libs),
                           str(tmp_path / "main.c"), "-o", str(tmp_path / "main"), "-lm"],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    run = subprocess.run([str(tmp_path / "main")], capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stderr
    # The last command, trig's p[0] eq_cos(y[1]) with p[0] = 1 and y[1] = 3: the project's
    # cosine to the bit (its Python), and the C library's within an ulp.
    from equilibrist.numeric import libm

    got = float(run.stdout.split()[-1])
    assert got == libm.cos(3.0)
    assert abs(got - math.cos(3.0)) <= math.ulp(math.cos(3.0))
