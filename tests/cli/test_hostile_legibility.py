"""What a newcomer reads and pastes: numbers printed as they are meant, numbers read as
written, advice that names the command's own options, progress on a long command, and the
README's commands that run as pasted."""

from __future__ import annotations

import json
import math
import re

import pytest

from equilibrist.cli.main import main

# A zero printed with a sign: "-0" standing alone (not -0.5, not 1e-05).
SIGNED_ZERO = re.compile(r"(?<![\w.])-0(?:\.0*)?(?![\w.])")


def _one_line(code: int, err: str, *words: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    for word in words:
        assert word in err, err


# -- signed zeros -----------------------------------------------------------------------

@pytest.mark.parametrize("system", ["cartpole", "acrobot"])
def test_show_prints_zeros_without_a_sign(capsys, system) -> None:
    assert main(["show", system]) == 0
    out = capsys.readouterr().out
    text = out[out.index("linearization at"):]
    assert not SIGNED_ZERO.search(text), text


def test_the_cartpole_without_friction_has_two_zero_poles_printed_as_0(capsys) -> None:
    # b_c = b_p = 0: the cart's position and speed are free, two poles at the origin;
    # its A has a zero where the friction would be (x_dot row, x_dot column).
    assert main(["linearize", "cartpole"]) == 0
    out = capsys.readouterr().out
    poles = next(line for line in out.splitlines() if line.startswith("open-loop poles:"))
    assert poles.split(":", 1)[1].split(", ").count("0") == 2, poles
    row = next(line for line in out.splitlines() if line.split()[:1] == ["x_dot"]
               and len(line.split()) == 5)
    assert row.split()[3] == "0", row


def _negative_zeros(obj: object, where: str = "") -> list[str]:
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _negative_zeros(v, f"{where}.{k}")]
    if isinstance(obj, list):
        return [p for k, v in enumerate(obj) for p in _negative_zeros(v, f"{where}[{k}]")]
    if isinstance(obj, float) and obj == 0.0 and math.copysign(1.0, obj) < 0:
        return [where]
    return []


@pytest.mark.parametrize("system", ["cartpole", "acrobot"])
def test_linearize_json_has_no_negative_zero_where_the_text_prints_0(capsys, system) -> None:
    assert main(["linearize", system, "--json"]) == 0
    raw = capsys.readouterr().out
    assert _negative_zeros(json.loads(raw)) == []
    assert "-0.0," not in raw and "-0.0\n" not in raw


# -- numbers as written ------------------------------------------------------------------

@pytest.mark.parametrize(("argv", "words"), [
    (["linearize", "cartpole", "--at", "theta=1_0"], ["--at theta", "'1_0'", "not a number"]),
    (["design", "cartpole", "--at", "theta=0_1"], ["--at theta", "'0_1'"]),
    (["linearize", "cartpole", "--input", "F=1_0"], ["--input F", "'1_0'"]),
    (["linearize", "cartpole", "--set", "m_p=1_0"], ["--set m_p", "'1_0'"]),
    (["design", "cartpole", "--q", "1_0,1,1,1"], ["--q", "'1_0'"]),
    (["linearize", "cartpole", "--at", "theta=\u0661"], ["--at theta", "not a number"]),
    (["roa", "cartpole", "--samples", "1_000"], ["--samples", "'1_000'", "whole number"]),
    (["roa", "cartpole", "--seed", "1_0"], ["--seed", "'1_0'", "whole number"]),
    (["simulate", "cartpole", "--seed", "1_0"], ["--seed", "'1_0'", "whole number"]),
    (["batch", "cartpole", "--runs", "2", "--seed", "1_0"], ["--seed", "'1_0'", "whole number"]),
    (["export", "cartpole", "--out", "never-written", "--seed", "1_0"],
     ["--seed", "'1_0'", "whole number"]),
    (["simulate", "cartpole", "--animate", "never.gif", "--fps", "1_0"], ["--fps", "'1_0'"]),
    (["simulate", "cartpole", "--animate", "never.gif", "--max-frames", "1_0"],
     ["--max-frames", "'1_0'"]),
])
def test_a_number_with_an_underscore_is_refused_in_one_line(capsys, argv, words) -> None:
    code = main(argv)
    _one_line(code, capsys.readouterr().err, *words)


@pytest.mark.parametrize("value", ["0.1", ".1", "+0.1", "1e-1", "1E-1", " 0.1"])
def test_ordinary_decimals_are_read(capsys, value) -> None:
    assert main(["linearize", "cartpole", "--at", f"theta={value}", "--json"]) == 0
    x0 = json.loads(capsys.readouterr().out)["x0"]
    assert x0[1] == 0.1


# -- the step limit's advice names the command's own options ------------------------------

def _options_of(capsys, command: str) -> set[str]:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    return set(re.findall(r"(?<![\w-])--[a-z][a-z-]*", capsys.readouterr().out))


def test_roas_step_limit_names_only_options_roa_takes_and_its_advice_works(
        capsys, monkeypatch) -> None:
    from equilibrist.sim import batch

    started: list[int] = []
    real = batch.simulate_batch
    monkeypatch.setattr(batch, "simulate_batch",
                        lambda *a, **k: started.append(k["runs"]) or real(*a, **k))
    # A physics step of a nanosecond: millions of steps a run, refused before any run.
    code = main(["roa", "cartpole", "--physics-step", "1e-9"])
    err = capsys.readouterr().err
    _one_line(code, err, "physics steps")
    assert started == []
    named = set(re.findall(r"(?<![\w-])--[a-z][a-z-]*", err))
    assert named and named <= _options_of(capsys, "roa"), named
    # A small analysis under a tiny bound: refused; asked for as the advice says, it runs.
    # (1009 runs of 3 samples of 5 steps: 15135 steps, which 1.51e+04 would not allow.)
    argv = ["roa", "cartpole", "--samples", "100", "--duration", "0.015", "--falsify", "0",
            "--certify", "off", "--no-progress", "--json"]
    code = main([*argv, "--max-steps", "1000"])
    err = capsys.readouterr().err
    _one_line(code, err, "--max-steps")
    asked = re.search(r"--max-steps (\S+)", err)
    assert asked is not None and started == []
    assert main([*argv, "--max-steps", asked.group(1)]) == 0
    assert json.loads(capsys.readouterr().out)["system"] == "cartpole"
    assert started


# -- roa's progress on stderr ---------------------------------------------------------------

ROA_SMALL = ["roa", "cartpole", "--samples", "100", "--duration", "0.2", "--falsify", "0",
             "--boxes", "1000"]


@pytest.mark.parametrize(("terminal", "extra", "shown"), [
    (True, [], True),
    (False, [], False),  # stderr to a file or a pipe: no bar
    (True, ["--no-progress"], False),
    (True, ["--json"], False),  # --json with stdout captured (not a terminal): for a script
], ids=["terminal", "not-a-terminal", "no-progress", "json"])
def test_roa_shows_progress_bars_on_a_terminal(capsys, monkeypatch, terminal, extra,
                                               shown) -> None:
    import sys

    import tqdm

    made: list[tuple[str | None, object]] = []

    class Recorded(tqdm.tqdm):
        def __init__(self, *args, **kwargs):
            made.append((kwargs.get("unit"), kwargs.get("file")))
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(tqdm, "tqdm", Recorded)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: terminal)
    assert main([*ROA_SMALL, *extra]) == 0
    capsys.readouterr()
    if shown:
        # A bar of each batch of runs and of the certificate's boxes, on stderr.
        assert {unit for unit, _ in made} == {"runs", "boxes"}, made
        assert all(file is sys.stderr for _, file in made)
    else:
        assert made == []


# -- the tour's commands (docs/tour.md) run as pasted ------------------------------------

def _readme_commands(word: str) -> list[str]:
    from pathlib import Path

    text = (Path(__file__).parents[2] / "docs" / "tour.md").read_text()
    blocks = re.findall(r"```sh\n(.*?)```", text, flags=re.S)
    return [line for block in blocks for line in block.splitlines()
            if line.startswith("equilibrist ") and word in line]


def test_the_readmes_gymnasium_model_command_runs_as_pasted(tmp_path) -> None:
    import os
    import subprocess
    import sys

    lines = _readme_commands("inverted_pendulum.xml")
    assert len(lines) == 1, lines
    # The shell of a user whose environment has equilibrist and Gymnasium: its python and
    # equilibrist first on PATH; an empty folder, as after a fresh clone elsewhere.
    bin_dir = os.path.dirname(sys.executable)
    env = dict(os.environ, PATH=bin_dir + os.pathsep + os.environ.get("PATH", ""))
    proc = subprocess.run(["bash", "-c", lines[0]], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr
    # Gymnasium's inverted pendulum: a slider (the cart) and a hinge (the pole).
    assert "inverted_pendulum.xml: linearization at" in proc.stdout
    assert "x0: slider = " in proc.stdout and "hinge = " in proc.stdout
    assert "(an equilibrium)" in proc.stdout
