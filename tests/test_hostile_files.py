"""A user's Python system file that misbehaves: one line naming the file, exit status 2.

A system file is the user's own code. Whatever it does wrong (exits, raises,
returns something that is not a model, prints, declares a spec that
contradicts itself) the command ends with one line that names the file and
what was expected, and its output stays the command's own.
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.errors import DefinitionError
from equilibrist.mechanics.spec import Input, Parameter, nonnegative, positive

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "my_cartpole.py"
# The example without its script part, and the places to plant code in it.
SOURCE = EXAMPLE.read_text().split("if __name__")[0]
AT_IMPORT = "SPEC = SystemSpec("
IN_DERIVE = '    """Kane\'s method on a particle (the cart) and a rigid body (the pole)."""\n'
assert AT_IMPORT in SOURCE and IN_DERIVE in SOURCE


def _file(folder: Path, name: str, *, at_import: str = "", in_derive: str = "") -> Path:
    text = SOURCE.replace(AT_IMPORT, at_import + "\n" + AT_IMPORT, 1)
    text = text.replace(IN_DERIVE, IN_DERIVE + in_derive, 1)
    path = folder / name
    path.write_text(text)
    return path


def _one_line(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(list(argv)) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err
    assert captured.out == ""
    return lines[0]


EXIT_CODES = st.one_of(st.none(), st.integers(-(2**40), 2**40), st.text(max_size=20))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(code=EXIT_CODES)
def test_sys_exit_at_import_is_a_refusal_not_an_exit(capsys, code: object) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = _file(Path(folder), "exits.py", at_import=f"import sys\nsys.exit({code!r})\n")
        line = _one_line(capsys, "linearize", str(path))
    assert str(path.resolve()) in line and "sys.exit" in line and "line " in line


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(code=EXIT_CODES, returned=st.sampled_from(["None", "42", "'model'", "d", "[d.q]"]))
def test_derive_that_exits_or_returns_no_model_is_one_line(capsys, code: object, returned: str) -> None:
    with tempfile.TemporaryDirectory() as folder:
        exits = _file(Path(folder), "exits.py", in_derive=f"    import sys\n    sys.exit({code!r})\n")
        line = _one_line(capsys, "linearize", str(exits))
        assert str(exits.resolve()) in line and "sys.exit" in line and "derive(d)" in line
        wrong = _file(Path(folder), "wrong.py", in_derive=f"    return {returned}\n")
        line = _one_line(capsys, "linearize", str(wrong))
        assert str(wrong.resolve()) in line and "derive(d) returned" in line
        assert "expected the model" in line


@pytest.mark.parametrize("error", ["RuntimeError('boom')", "KeyError('x')", "ZeroDivisionError()",
                                   "AttributeError('no such body')", "RecursionError()"])
def test_derive_that_raises_names_the_file_and_the_line(capsys, tmp_path: Path, error: str) -> None:
    path = _file(tmp_path, "raises.py", in_derive=f"    raise {error}\n")
    line = _one_line(capsys, "linearize", str(path))
    kind = error.split("(", maxsplit=1)[0]
    assert str(path.resolve()) in line and f"{kind}:" in line and "line " in line
    assert "expected derive(d) to return the model" in line


def test_a_derive_error_through_the_api_is_a_definition_error(tmp_path: Path) -> None:
    path = _file(tmp_path, "none.py", in_derive="    return None\n")
    with pytest.raises(DefinitionError, match="returned NoneType"):
        get_system(str(path))


def test_ctrl_c_in_a_system_file_still_interrupts(tmp_path: Path) -> None:
    path = _file(tmp_path, "interrupted.py", at_import="raise KeyboardInterrupt\n")
    with pytest.raises(KeyboardInterrupt):
        get_system(str(path))
    path = _file(tmp_path, "interrupted_later.py", in_derive="    raise KeyboardInterrupt\n")
    with pytest.raises(KeyboardInterrupt):
        get_system(str(path))


def test_printing_file_leaves_json_output_whole(capsys, tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    from equilibrist.numeric import cache

    folder = tmp_path / "cache"  # a fresh cache: the derivation runs (and prints)
    folder.mkdir(mode=0o700)
    monkeypatch.setenv("EQUILIBRIST_CACHE", str(folder))
    monkeypatch.setattr(cache, "_MEMO", {})
    path = _file(tmp_path, "chatty.py", at_import="print('loading my rig')\n",
                 in_derive="    print('deriving', d.q)\n")
    assert main(["linearize", str(path), "--json"]) == 0
    captured = capsys.readouterr()
    data = json.loads(captured.out)  # stdout is the JSON document and nothing else
    assert data["system"] == str(path.resolve())
    assert "loading my rig" in captured.err and "deriving" in captured.err


REAL = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=200, deadline=None)
@given(low=REAL, width=st.floats(0.0, 1e6), default=st.floats(width=64),
       low_open=st.booleans(), high_open=st.booleans())
def test_parameter_default_must_lie_in_its_own_range(low: float, width: float, default: float,
                                                     low_open: bool, high_open: bool) -> None:
    high = low + width
    inside = math.isfinite(default) and (
        (default > low if low_open else default >= low) and (default < high if high_open else default <= high)
    )
    make = lambda: Parameter("k", default, "N/m", "a spring", low=low, high=high,  # noqa: E731
                             low_open=low_open, high_open=high_open)
    if inside:
        assert make().default == default
    else:
        with pytest.raises(DefinitionError, match=r"'k'.*expected"):
            make()


@pytest.mark.parametrize(
    "build",
    [lambda: positive("m", 0.0, "kg", "mass"), lambda: positive("m", -2.0, "kg", "mass"),
     lambda: nonnegative("b", -1e-9, "N*s/m", "friction"), lambda: positive("m", math.nan, "kg", "mass"),
     lambda: positive("m", "heavy", "kg", "mass"), lambda: Parameter("k", 1.0, "", "", low=2.0, high=1.0),
     lambda: Input("F", "N", "force", 15.0, -15.0), lambda: Input("F", "N", "force", -math.inf, 1.0),
     lambda: Input("F", "N", "force", "low", 1.0)],
    ids=["zero-mass", "negative-mass", "negative-friction", "nan", "text", "empty-range",
         "inverted-limits", "infinite-limit", "text-limit"],
)
def test_spec_refuses_values_outside_their_own_range(build) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(DefinitionError, match="expected"):
        build()


def test_file_with_a_default_out_of_range_is_one_line(capsys, tmp_path: Path) -> None:
    path = tmp_path / "bad_default.py"
    path.write_text(SOURCE.replace('positive("m_c", 2.0,', 'positive("m_c", -2.0,'))
    line = _one_line(capsys, "linearize", str(path))
    assert str(path.resolve()) in line and "m_c" in line and "(0, inf)" in line


# -- the control layer: complex matrices are refused, not cut to their real part ----------
def _design_args(which: str, imaginary: float) -> tuple[str, tuple[object, ...]]:
    """A regulator or estimator problem with one matrix made complex (1 + imaginary j times it)."""
    import numpy as np

    A = np.array([[0.0, 1.0], [2.0, 0.0]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[1.0, 0.0]])
    values = {"A": A, "B": B, "C": C, "G": np.eye(2), "Q": np.eye(2), "R": np.eye(1),
              "QN": np.eye(2), "RN": np.eye(1)}
    values[which] = values[which] * (1.0 + 1j * imaginary)
    if which in ("A", "B", "Q", "R"):
        return "lqr", (values["A"], values["B"], values["Q"], values["R"])
    return "lqe", (values["A"], values["G"], values["C"], values["QN"], values["RN"])


@settings(max_examples=60, deadline=None)
@given(which=st.sampled_from(["A", "B", "Q", "R", "G", "C", "QN", "RN"]),
       imaginary=st.one_of(st.just(0.0), st.floats(-1e3, 1e3, allow_nan=False)),
       discrete=st.booleans(), as_list=st.booleans())
def test_complex_matrices_are_refused_as_complex(which: str, imaginary: float, discrete: bool,
                                                 as_list: bool) -> None:
    from equilibrist.control import riccati
    from equilibrist.errors import EquilibristError

    kind, args = _design_args(which, imaginary)
    order = ("A", "B", "Q", "R") if kind == "lqr" else ("A", "G", "C", "QN", "RN")
    position = order.index(which)
    if as_list:  # Python complex numbers in nested lists, not an array
        args = tuple(a.tolist() if i == position else a for i, a in enumerate(args))  # type: ignore[union-attr]
    solve = getattr(riccati, ("d" if discrete else "") + kind)
    with pytest.raises(EquilibristError) as info:
        solve(*args)
    message = str(info.value)
    assert "must be real" in message and which in message, message
    assert "stabilizable" not in message and "detectable" not in message


# -- a Python controller that returns something other than numbers -------------------------
NOT_NUMBERS = st.one_of(
    st.text(max_size=8), st.text(alphabet="0123456789.", min_size=1, max_size=4).map(lambda v: [v]),
    st.just({"F": 1.0}), st.builds(object).map(lambda v: [v]),
    st.complex_numbers(allow_nan=False, allow_infinity=False).map(lambda c: [c]),
    st.just([[1.0], [2.0, 3.0]]), st.just([True]),
)


class _Returns:
    """A PythonController that returns *value* as its command."""

    rate = 100.0
    outputs = None
    estimate = None

    def __init__(self, value: object) -> None:
        self.value = value

    def reset(self) -> None:
        pass

    def output(self, t: float, y: object, r: object) -> object:
        return self.value

    def update(self, t: float, y: object, r: object, u_applied: object) -> None:
        pass


class _Steps:
    """An object of the older step interface that returns *value*."""

    def __init__(self, value: object) -> None:
        self.value = value

    def step(self, t: float, y: object, r: object) -> object:
        return self.value


@settings(max_examples=40, deadline=None)
@given(value=NOT_NUMBERS, kind=st.sampled_from(["function", "step", "protocol"]))
def test_a_controller_returning_no_numbers_is_named(value: object, kind: str) -> None:
    from equilibrist.errors import SimulationError
    from equilibrist.sim.run import simulate

    def my_function(t, y, r):  # type: ignore[no-untyped-def]
        return value

    controller = {"function": my_function, "step": _Steps(value), "protocol": _Returns(value)}[kind]
    name = {"function": "my_function", "step": "_Steps", "protocol": "_Returns"}[kind]
    with pytest.raises(SimulationError) as info:
        simulate(get_system("cartpole"), controller, duration=0.05, rate=100.0)
    message = str(info.value)
    assert "\n" not in message
    assert f"the controller {name} returned" in message and "expected its inputs as real numbers" in message


def test_a_checked_controller_still_runs_and_keeps_its_own_state() -> None:
    import numpy as np

    from equilibrist.sim.run import simulate

    class Counting(_Returns):
        calls = 0

        def output(self, t: float, y: object, r: object) -> object:
            self.calls += 1
            return [np.float32(0.5)]

    mine = Counting(None)
    result = simulate(get_system("cartpole"), mine, duration=0.1, rate=100.0)
    assert mine.calls >= 10 and float(result.command("F")[0]) == 0.5
    steps = _Steps((0.25,))
    for _ in range(3):  # the same adapter, checked once however often it runs
        simulate(get_system("cartpole"), steps, duration=0.05, rate=100.0)
