"""Hostile command lines of identify, sweep and export: one line, exit 2, nothing lost.

And a command that is signalled ends as a shell expects: 130 after Ctrl-C,
143 after SIGTERM, with its one line and nothing half-written.
"""

from __future__ import annotations

import math
import signal
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.support.signals import (
    STOPS_WITHIN,
    signal_while_working,
    start_at_work,
    start_held,
    when_held,
)

from equilibrist.cli.main import main
from equilibrist.study import store


def _one_line(code: int, err: str, *words: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    for word in words:
        assert word in err, err

# -- signals ---------------------------------------------------------------------------

SIGNALLED = {
    # Each is signalled past the start (the handlers are set before 0.3 s of CPU) and
    # before its end, whatever the machine's speed: held at a known point of its work
    # (tests.support.signals.start_held), or once its work has begun and gone on for half
    # a second of CPU (start_at_work: the work itself runs unchanged, for minutes).
    # show: held where it writes the equations as LaTeX, its header printed.
    "show": (["show", "double_cartpole", "--latex"], "held",
             "equilibrist.mechanics.printing:equations_latex"),
    # sweep: 400 points of 2000 runs each, minutes of work, signalled in its first chunk.
    "sweep": (["sweep", "cartpole", "--vary", "m_p=0.2:2:400", "--runs", "2000",
               "--no-progress", "--out", "s.parquet"], "at work",
              "equilibrist.study.runner:evaluate_chunk"),
    # export: the MPC's recorded run, then the compiles that measure it, where it is held:
    # its files made in memory, none written yet.
    "export": (["export", "cartpole", "--controller", "mpc", "--out", "lib"], "held",
               "equilibrist.native.size:measure"),
}


@pytest.mark.parametrize("command", sorted(SIGNALLED))
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signalled_command_exits_130_or_143(tmp_path, command, signum) -> None:
    argv, how, at = SIGNALLED[command]
    if how == "held":
        proc, ready = start_held(argv, tmp_path, at), when_held
    else:
        proc, ready = start_at_work(argv, tmp_path, at)
    code, _, err, took = signal_while_working(proc, signum, ready)
    assert code == (143 if signum == signal.SIGTERM else 130), err.decode()
    assert "Traceback" not in err.decode()
    assert err.decode().strip().splitlines()[-1].startswith("equilibrist: interrupted")
    assert took < STOPS_WITHIN, f"took {took:.1f} s to stop"
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# -- sweep: the user's files stay, damaged parts folders are named -----------------------

SWEEP = ["sweep", "cartpole", "--vary", "m_p=0.1:0.3:2", "--runs", "3", "--duration", "0.5",
         "--seed", "3", "--no-progress", "--chunk-size", "1"]


def _foreign_parquet(path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table({"x": [1.0, 2.0]}), path)


def _interrupted_study(out: Path, m_p: str = "0.1:0.3:2") -> Path:
    """A study of two chunks interrupted after its first: its parts folder."""
    from equilibrist.study import make_study, run_study

    study = make_study("cartpole", vary={"m_p": m_p}, runs=3, duration=0.5, seed=3)

    def stop(chunk: int, done: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(study, out, chunk_size=1, on_chunk=stop)
    parts = out.with_name(out.name + ".parts")
    assert sorted(p.name for p in parts.iterdir()) == ["chunk-000000.parquet", "study.json"]
    return parts


@pytest.mark.parametrize("kind", ["text", "foreign parquet"])
def test_sweep_never_overwrites_a_users_file(tmp_path, capsys, kind) -> None:
    out = tmp_path / "table.parquet"
    if kind == "text":
        out.write_text("the user's own file")
    else:
        _foreign_parquet(out)
    before = out.read_bytes()
    for extra in ([], ["--resume"], ["--resume", "--force"]):
        code = main([*SWEEP, "--out", str(out), *extra])
        _one_line(code, capsys.readouterr().err, str(out))
        assert out.read_bytes() == before
        assert sorted(p.name for p in tmp_path.iterdir()) == ["table.parquet"]
    assert main([*SWEEP, "--out", str(out), "--force"]) == 0
    assert out.read_bytes() != before
    # A study table is equilibrist's own: written again without --force.
    assert main([*SWEEP, "--out", str(out)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.parquet"]


def test_resume_keeps_the_users_files_in_the_parts_folder(tmp_path, capsys) -> None:
    out = tmp_path / "table.parquet"
    parts = _interrupted_study(out)
    (parts / "notes.txt").write_text("the user's notes")
    (parts / "chunk-9.parquet").write_text("not a part's name")
    assert main([*SWEEP, "--out", str(out), "--resume"]) == 0, capsys.readouterr().err
    assert out.exists()
    assert sorted(p.name for p in parts.iterdir()) == ["chunk-9.parquet", "notes.txt"]
    assert (parts / "notes.txt").read_text() == "the user's notes"


@pytest.mark.parametrize("manifest", ["[1, 2]", '"a string"', "3", "null", '{"study": 3}',
                                      "{not json", ""])
def test_resume_names_a_damaged_manifest(tmp_path, capsys, manifest) -> None:
    out = tmp_path / "table.parquet"
    parts = _interrupted_study(out)
    (parts / "study.json").write_text(manifest)
    code = main([*SWEEP, "--out", str(out), "--resume"])
    _one_line(code, capsys.readouterr().err, "study.json")
    assert sorted(p.name for p in parts.iterdir()) == ["chunk-000000.parquet", "study.json"]
    assert not out.exists()


@pytest.mark.parametrize("chunk", ["chunk-000000.parquet", "chunk-000001.parquet"])
@pytest.mark.parametrize("kind", ["text", "foreign parquet", "another study's part"])
def test_resume_names_a_foreign_part_and_keeps_it(tmp_path, capsys, chunk, kind) -> None:
    out = tmp_path / "table.parquet"
    parts = _interrupted_study(out)
    foreign = parts / chunk
    if kind == "text":
        foreign.write_text("the user's own file")
    elif kind == "foreign parquet":
        _foreign_parquet(foreign)
    else:
        (tmp_path / "other").mkdir()
        other = _interrupted_study(tmp_path / "other" / "t.parquet", m_p="0.1:0.4:2")
        foreign.write_bytes((other / "chunk-000000.parquet").read_bytes())
    before = foreign.read_bytes()
    code = main([*SWEEP, "--out", str(out), "--resume"])
    _one_line(code, capsys.readouterr().err, chunk)
    assert foreign.read_bytes() == before
    assert not out.exists()


@pytest.mark.parametrize("address", ["not a url", "http://localhost:8786", "tcp://", "ftp://a:1",
                                     "tcp://has space:8786"])
def test_a_scheduler_address_that_is_not_one_is_refused(tmp_path, capsys, address) -> None:
    out = tmp_path / "table.parquet"
    code = main([*SWEEP, "--out", str(out), "--scheduler", address])
    _one_line(code, capsys.readouterr().err, "--scheduler", "tcp://HOST:PORT")
    assert list(tmp_path.iterdir()) == []


def test_more_workers_than_cores_are_refused(tmp_path, capsys, monkeypatch) -> None:
    from equilibrist.study import runner

    def never(workers):
        raise AssertionError("a local cluster was started")

    monkeypatch.setattr(runner, "_local_cluster", never)
    out = tmp_path / "table.parquet"
    code = main([*SWEEP, "--out", str(out), "--workers", "1000"])
    _one_line(code, capsys.readouterr().err, "--workers 1000", "cores")
    assert list(tmp_path.iterdir()) == []


# -- sizes are checked before anything is allocated ------------------------------------

@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(10_000_001, 10**30), log=st.booleans())
def test_a_grid_too_large_is_refused_before_it_is_allocated(tmp_path, capsys, n, log) -> None:
    out = tmp_path / "table.parquet"
    vary = f"m_p=0.5:2:{n}" + (":log" if log else "")
    code = main(["sweep", "cartpole", "--vary", vary, "--out", str(out), "--no-progress"])
    _one_line(code, capsys.readouterr().err, "--vary m_p", "at most 10000000")
    assert not out.exists()


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(counts=st.lists(st.integers(1, 10**20), min_size=1, max_size=3).filter(
    lambda c: math.prod(c) > 100_000))
def test_a_region_of_attraction_grid_too_large_is_refused(tmp_path, capsys, counts) -> None:
    out = tmp_path / "table.parquet"
    roa = [f"{s}=-0.1:0.1:{n}" for s, n in zip(("theta", "x", "theta_dot"), counts, strict=False)]
    code = main(["sweep", "cartpole", "--vary", "m_p=0.5:2:2", "--roa", *roa, "--out", str(out),
                 "--no-progress"])
    _one_line(code, capsys.readouterr().err, "--roa", "at most 100000")
    assert not out.exists()


# -- export: sizes, durations and options it cannot use --------------------------------

@pytest.mark.parametrize(("extra", "words"), [
    (["--controller", "mpc", "--horizon", "10000"], ["--horizon 10000", "at most"]),
    (["--controller", "mpc", "--horizon", "1000000"], ["--horizon 1000000", "at most"]),
    (["--controller", "mpc", "--duration", "1e5"], ["--duration", "at most 10000 samples"]),
    (["--controller", "swingup", "--duration", "1e5"], ["--duration", "at most 10000 samples"]),
    (["--duration", "1e5"], ["--duration", "at most 10000 samples"]),
    (["--controller", "lqr", "--duration", "50.1"], ["--duration", "50 s at 200 Hz"]),
    (["--seed", "-1"], ["--seed -1", ">= 0"]),
    (["--horizon", "0"], ["--horizon", "lqg controller takes none"]),
    (["--controller", "lqr", "--horizon", "30"], ["--horizon", "lqr controller takes none"]),
    (["--controller", "swingup", "--horizon", "30"], ["--horizon", "swingup"]),
    (["--controller", "lqr", "--balance", "lqg"], ["--balance", "lqr controller takes none"]),
])
def test_export_refuses_what_it_cannot_use_before_any_work(tmp_path, capsys, monkeypatch,
                                                           extra, words) -> None:
    from equilibrist.controllers.kinds import ControllerKind

    def never(*args, **kwargs):
        raise AssertionError("a controller was built")

    monkeypatch.setattr(ControllerKind, "make", never)
    code = main(["export", "cartpole", "--out", str(tmp_path / "lib"), *extra])
    _one_line(code, capsys.readouterr().err, *words)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("out", ["", " "])
def test_export_refuses_an_empty_out(tmp_path, capsys, monkeypatch, out) -> None:
    monkeypatch.chdir(tmp_path)
    code = main(["export", "cartpole", "--out", out])
    _one_line(code, capsys.readouterr().err, "--out")
    assert list(tmp_path.iterdir()) == []


def test_the_api_bounds_the_recorded_run_too(tmp_path) -> None:
    from equilibrist.control.design import design
    from equilibrist.errors import ExportError
    from equilibrist.export import export_c
    from equilibrist.numeric.lookup import get_system

    result = design(get_system("cartpole"), rate=200.0)
    with pytest.raises(ExportError, match="at most 10000 samples"):
        export_c(result, tmp_path / "lib", duration=1e5)
    assert list(tmp_path.iterdir()) == []


# -- identify: the user's files, bounded work, logs that say nothing ---------------------

@pytest.fixture(scope="module")
def cart_log(tmp_path_factory) -> Path:
    """A 3 s closed-loop log of the cart-pole (200 Hz), written by the command line."""
    path = tmp_path_factory.mktemp("ident") / "run.csv"
    assert main(["simulate", "cartpole", "--duration", "3", "--excite", "prbs:20:0.2",
                 "--seed", "3", "--out", str(path), "--json"]) == 0
    return path


@pytest.fixture
def no_fit(monkeypatch):
    """identify's fit replaced by a failure: what is refused is refused before it."""
    from equilibrist import ident

    def never(*args, **kwargs):
        raise AssertionError("the fit ran")

    monkeypatch.setattr(ident, "identify", never)


@pytest.mark.parametrize("content", ["the user's notes", '{"m_p": 1.0}', "[]"])
def test_identify_never_overwrites_a_users_file(tmp_path, capsys, cart_log, no_fit,
                                                content) -> None:
    out = tmp_path / "params.json"
    out.write_text(content)
    code = main(["identify", "cartpole", str(cart_log), "--free", "m_p", "--out", str(out)])
    _one_line(code, capsys.readouterr().err, str(out), "--force")
    assert out.read_text() == content
    assert sorted(p.name for p in tmp_path.iterdir()) == ["params.json"]
    # --force goes on to the fit.
    with pytest.raises(AssertionError, match="the fit ran"):
        main(["identify", "cartpole", str(cart_log), "--free", "m_p", "--out", str(out), "--force"])


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(step=st.floats(min_value=1e-300, max_value=4.9e-6))
def test_an_integration_step_too_fine_is_refused_before_the_fit(capsys, cart_log, step) -> None:
    # The log's samples are 5 ms: at most 1000 RK4 steps each, a step >= 5e-6 s.
    code = main(["identify", "cartpole", str(cart_log), "--free", "m_p", "--max-step", repr(step)])
    _one_line(code, capsys.readouterr().err, "--max-step", "at most 1000 RK4 steps")


@pytest.mark.parametrize("level", ["0", "-0", "0.0"])
def test_a_sensor_without_noise_is_refused(capsys, cart_log, no_fit, level) -> None:
    code = main(["identify", "cartpole", str(cart_log), "--free", "m_p", "--sensor-noise",
                 f"theta={level}"])
    _one_line(code, capsys.readouterr().err, "--sensor-noise theta", "> 0")


def test_the_api_refuses_a_sensor_without_noise(cart_log) -> None:
    from equilibrist.ident import identify, read_log
    from equilibrist.ident.log import IdentificationError
    from equilibrist.numeric.lookup import get_system

    system = get_system("cartpole")
    with pytest.raises(IdentificationError, match="> 0"):
        identify(system, read_log(system, cart_log), ["m_p"], sensor_noise={"theta": 0.0})


@pytest.mark.parametrize("column", ["all", "theta"])
def test_a_log_whose_output_never_moves_is_one_line(tmp_path, capsys, cart_log, column) -> None:
    lines = cart_log.read_text().splitlines()
    comments = [line for line in lines if line.startswith("#")]
    rows = [line for line in lines if not line.startswith("#")]
    header = rows[0].split(",")
    flat = [k for k, name in enumerate(header) if k > 0 and (column == "all" or
                                                           name.split(" ")[0] == column)]
    body = []
    for row in rows[1:]:
        cells = row.split(",")
        body.append(",".join("0" if k in flat else c for k, c in enumerate(cells)))
    log = tmp_path / "flat.csv"
    log.write_text("\n".join([*comments, rows[0], *body]) + "\n")
    code = main(["identify", "cartpole", str(log), "--free", "m_p"])
    _one_line(code, capsys.readouterr().err, "throughout")


@pytest.mark.parametrize("extra", [[], ["--max-step", "6e-6"]], ids=["default", "finest-step"])
def test_ctrl_c_stops_identify_at_once(tmp_path, extra) -> None:
    # A 30 s log: its fit takes minutes of CPU, signalled once the fit has gone on for half a
    # second of CPU from its first call of least_squares (after the imports, the log and the
    # first shooting fit's set-up: about 2.5 s of CPU here, whatever the machine's speed);
    # at the finest step accepted (1000 RK4 steps a sample) too.
    folder = tmp_path / "work"
    folder.mkdir()
    assert main(["simulate", "cartpole", "--duration", "30", "--excite", "prbs:20:0.2",
                 "--seed", "4", "--out", str(folder / "run.csv"), "--json"]) == 0
    for signum, status in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):
        proc, ready = start_at_work(["identify", "cartpole", "run.csv", "--free", "m_p,l", "--out",
                                     "p.json", *extra], folder, "scipy.optimize:least_squares")
        code, _, err, took = signal_while_working(proc, signum, ready)
        assert code == status, err.decode()
        assert err.decode().strip() == "equilibrist: interrupted"
        assert took < STOPS_WITHIN, f"took {took:.1f} s to stop"
        assert sorted(p.name for p in folder.iterdir()) == ["run.csv"]


@pytest.mark.parametrize(("extra", "words"), [
    (["--duration", "1e308"], ["--duration 1e+308 s at 200 Hz", "at most 10000000"]),
    (["--duration", "50001"], ["--duration 50001 s", "at most 10000000"]),
    (["--vary", "rate=100:1e300:3", "--duration", "1"], ["--duration 1 s at 1e+300 Hz"]),
])
def test_a_run_too_long_is_refused(tmp_path, capsys, extra, words) -> None:
    out = tmp_path / "table.parquet"
    code = main(["sweep", "cartpole", "--vary", "m_p=0.5:2:2", *extra, "--out", str(out),
                 "--no-progress"])
    _one_line(code, capsys.readouterr().err, *words)
    assert not out.exists()


# -- odd values anywhere on a sweep's command line ---------------------------------------

ODD = ["nan", "inf", "-inf", "1e400", "-1e400", "", " ", "abc", "0", "-0", "-1", "1e-300",
       "1e308", "=", ":::", "1,2", ",", "0x10", "1_0", "1e9", "-1e9", "1000000000",
       "10000000000000000000000", "0.1:0.3:2", "0.1:0.3:1000000000", "0.1:0.3:2:log",
       "-1:1:100000000", "not a url", "http://h:1", "tcp://"]
SWEEP_OPTIONS = {"--vary": "m_p={}", "--roa": "theta={}", "--x0": "theta={}", "--spread": "l={}",
                 "--runs": "{}", "--duration": "{}", "--seed": "{}", "--workers": "{}",
                 "--scheduler": "{}", "--chunk-size": "{}", "--sample": "random:{}",
                 "--rate": "{}", "--noise": "{}", "--threads": "{}"}


class _Reached(Exception):
    """The sweep got past every check to its parts folder."""


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(picks=st.lists(st.tuples(st.sampled_from(sorted(SWEEP_OPTIONS)), st.sampled_from(ODD)),
                      min_size=1, max_size=3))
def test_odd_sweep_command_lines_are_one_line(tmp_path_factory, capsys, monkeypatch, picks) -> None:

    def reached(self, *, resume):
        raise _Reached

    monkeypatch.setattr(store.Store, "open", reached)
    folder = tmp_path_factory.mktemp("sweep")
    argv = ["sweep", "cartpole", "--vary", "l=0.4,0.5", "--no-progress",
            "--out", str(folder / "t.parquet")]
    for option, value in picks:
        argv += [option, SWEEP_OPTIONS[option].format(value)]
    _refused_or_reached(argv, folder, capsys)


def _refused_or_reached(argv: list[str], folder, capsys) -> None:
    """*argv* is refused in one line with nothing written, or reaches the work it asks for."""
    try:
        code = main(argv)
    except _Reached:
        return
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert list(folder.iterdir()) == []


EXPORT_OPTIONS = {"--rate": "{}", "--duration": "{}", "--seed": "{}", "--horizon": "{}",
                  "--controller": "{}", "--q": "{},1,1,1", "--r": "{}", "--set": "m_p={}"}
EXPORT_ODD = [*ODD, "mpc", "swingup", "lqr", "none", "50", "50.01", "204", "205"]


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(picks=st.lists(st.tuples(st.sampled_from(sorted(EXPORT_OPTIONS)), st.sampled_from(EXPORT_ODD)),
                      min_size=1, max_size=3))
def test_odd_export_command_lines_are_one_line(tmp_path_factory, capsys, monkeypatch, picks) -> None:
    import importlib

    def reached(*args, **kwargs):
        raise _Reached

    monkeypatch.setattr(importlib.import_module("equilibrist.controllers.kinds").ControllerKind,
                        "make", reached)
    monkeypatch.setattr(importlib.import_module("equilibrist.control.design"), "design", reached)
    folder = tmp_path_factory.mktemp("export")
    argv = ["export", "cartpole", "--out", str(folder / "lib")]
    for option, value in picks:
        argv += [option, EXPORT_OPTIONS[option].format(value)]
    _refused_or_reached(argv, folder, capsys)
