"""No consumer above the registry asks a kind's name: a kind that is the LQG's record under
another name (``twinlqg``) is, to the playground's session, its region of attraction, the
export and the ``hil`` command, the LQG itself. Its independent truth is the LQG's own run,
slice, library and hello, which the renamed kind must reproduce to the bit; a consumer that
compared the name with ``"lqg"`` would run the open loop, certify nothing, refuse the export
or refuse the device instead. The same holds of the swing-up's record renamed
(``twinswingup``: the track alone ends its run, and leaving it brings the angles back within
half a turn) and of the time-varying LQR's (``twintvlqr``: offered, refused and kept out of
the region of attraction as the time-varying LQR is)."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from equilibrist.controllers import kinds

TWIN = "twinlqg"


@pytest.fixture
def twin() -> Iterator[str]:
    """The LQG's record under another name, registered in this process (the project's
    kinds are records, so a plug-in of one's own could be exactly this)."""
    kinds.register(dataclasses.replace(kinds.get("lqg"), name=TWIN, label="LQG twin",
                                       order=100))
    try:
        yield TWIN
    finally:
        kinds.unregister(TWIN)


@pytest.fixture
def twins() -> Iterator[dict[str, str]]:
    """The swing-up's and the time-varying LQR's records, each under another name (and
    nothing else changed), registered in this process: ``{original: renamed}``."""
    names = {"swingup": "twinswingup", "tvlqr": "twintvlqr"}
    for original, renamed in names.items():
        kinds.register(dataclasses.replace(kinds.get(original), name=renamed, order=100))
    try:
        yield names
    finally:
        for renamed in names.values():
            kinds.unregister(renamed)


def _session_run(controller: str) -> dict[str, np.ndarray]:
    from equilibrist.web.session import Session
    from equilibrist.web.session_design import Catalogue

    session = Session(Catalogue.default(), "cartpole", seed=3)
    session.settings = dataclasses.replace(session.settings, controller=controller)
    session.plant = None
    session.x[1] += 0.05  # off the operating point: the loop has work to do
    rows: dict[str, list[Any]] = {"x": [], "u": [], "xhat": []}
    for _ in range(150):
        session._sample()
        rows["x"].append(session.x.copy())
        rows["u"].append(session.u_cmd.copy())
        rows["xhat"].append(np.array(session.xhat))
    return {k: np.array(v) for k, v in rows.items()}


def test_the_playground_runs_a_renamed_lqg_as_the_lqg(twin: str) -> None:
    lqg, renamed, off = _session_run("lqg"), _session_run(twin), _session_run("off")
    for key in ("x", "u", "xhat"):
        np.testing.assert_array_equal(renamed[key], lqg[key])
    # The open loop is another run: the comparison above can tell them apart.
    assert not np.array_equal(off["u"], lqg["u"])


def _slice(controller: str) -> dict[str, Any]:
    """The playground's region of attraction of *controller* on the cart-pole: the slice's
    frame, without what names the request (its id, the controller, its label, the time)."""
    from equilibrist.web.session import Session
    from equilibrist.web.session_design import Catalogue

    session = Session(Catalogue.default(), "cartpole", seed=3)
    session.settings = dataclasses.replace(session.settings, controller=controller)
    job = session.roa_job()
    assert job is not None
    frame = job.run_slice()
    return {k: v for k, v in frame.items() if k not in ("id", "controller", "label", "seconds")}


def test_the_playground_shows_the_region_of_attraction_of_a_renamed_lqg_as_the_lqgs(
        twin: str) -> None:
    lqg, renamed = _slice("lqg"), _slice(twin)
    # The LQG's slice is followed by its LQR's certificate; the renamed LQG's the same.
    assert lqg["certificate"] == "computing"
    assert renamed == lqg


def test_the_playground_keeps_a_renamed_tvlqr_out_of_the_region_of_attraction(
        twins: dict[str, str]) -> None:
    from equilibrist.web.session import Session
    from equilibrist.web.session_design import Catalogue, SessionError

    said = {}
    for name in ("tvlqr", twins["tvlqr"]):
        session = Session(Catalogue.default(), "cartpole", seed=3)
        session.settings = dataclasses.replace(session.settings, controller=name)
        with pytest.raises(SessionError) as refused:
            session.roa_job()
        said[name] = str(refused.value)
    assert "follows a swing-up plan from hanging" in said["tvlqr"]
    assert said[twins["tvlqr"]] == said["tvlqr"]  # the same label: the same words


@pytest.mark.parametrize("system", ["cartpole", "seesaw"])
def test_the_playground_offers_renamed_kinds_as_their_originals(
        system: str, twin: str, twins: dict[str, str]) -> None:
    """The picker's entries (available, or refused with the reason) and the page's list of
    controllers: a renamed kind is offered where and as its original is (the seesaw has no
    hanging position: no swing-up, no plan; the cart-pole has both)."""
    from equilibrist.web.session import Session
    from equilibrist.web.session_design import Catalogue

    described = Session(Catalogue.default(), system, seed=3).describe()
    offered = described["controller_options"]
    entries = {o["name"]: o for o in offered}
    assert [o["name"] for o in offered] == list(described["controllers"])
    for original, renamed in {"lqg": twin, **twins}.items():
        assert renamed in described["controllers"]
        mine, theirs = dict(entries[renamed]), dict(entries[original])
        for entry in (mine, theirs):
            entry.pop("name"), entry.pop("label"), entry.pop("short_label")
        assert mine == theirs, (renamed, mine, theirs)
    hanging = system == "cartpole"
    assert entries["tvlqr"]["available"] is hanging and entries["swingup"]["available"] is hanging


#: The facts of its kind's record the page reads from a ``controller_options`` entry.
FACTS = ("loop", "linear", "from_any_state", "planned", "solves_qp", "open_loop")


def test_the_picker_entries_carry_what_the_page_reads_of_each_record(
        twin: str, twins: dict[str, str]) -> None:
    """Each entry of the ``system`` frame's ``controller_options`` carries its record's facts
    (the page shows a controller by them, never by its name): a renamed kind's are its
    original's, and the originals' are what their records say (the swing-up comes up from any
    state, the time-varying LQR is planned, the MPC solves a QP, the LQG's loop has its
    filter, ``off`` is the open loop)."""
    from equilibrist.web.protocol import kind_name
    from equilibrist.web.session import Session
    from equilibrist.web.session_design import Catalogue

    entries = {o["name"]: o for o in
               Session(Catalogue.default(), "cartpole", seed=3).describe()["controller_options"]}
    for name, entry in entries.items():
        record = kinds.get(kind_name(name))
        assert {f: entry.get(f, "missing") for f in FACTS} == \
            {f: getattr(record, f) for f in FACTS}, name
        assert entry.get("short_label") == record.label.split(" (")[0], name
    for original, renamed in {"lqg": twin, **twins}.items():
        assert {f: entries[renamed][f] for f in FACTS} == {f: entries[original][f] for f in FACTS}
    assert entries[twins["swingup"]]["from_any_state"] is True
    assert entries[twins["tvlqr"]]["planned"] is True
    assert entries[twin]["loop"] == "lqg"
    assert entries["mpc"]["solves_qp"] is True and entries["off"]["open_loop"] is True
    assert [entries[n]["short_label"] for n in ("swingup", "tvlqr", "off")] == \
        ["Swing-up", "Time-varying LQR", "Off"]


def _compared_names(text: str, names: set[str]) -> list[str]:
    """The string literals of *text* (JavaScript) that equal one of *names* and are compared:
    beside ``===``, ``!==``, ``==`` or ``!=``, after ``case``, or in an array literal whose
    ``includes`` is asked."""
    literal = r"""(?:"([^"\\\n]*)"|'([^'\\\n]*)')"""
    found = []
    for pattern in (rf"[=!]==?\s*{literal}", rf"{literal}\s*[=!]==?", rf"\bcase\s+{literal}"):
        for m in re.finditer(pattern, text):
            found.append(m.group(1) if m.group(1) is not None else m.group(2))
    for m in re.finditer(r"\[([^\[\]]*)\]\s*\.\s*includes\s*\(", text):
        found += [a or b for a, b in re.findall(literal, m.group(1))]
    return [s for s in found if s in names]


def test_the_page_compares_no_kind_name() -> None:
    """The page's scripts branch on the kinds' facts the ``system`` frame carries, never on a
    kind's name: no string literal equal to a kind's name (or ``off``) is compared."""
    from equilibrist import web
    from equilibrist.web.protocol import OFF

    names = {k.name for k in kinds.all_kinds()} | {OFF}
    static = Path(web.__file__).parent / "static"
    # The check finds what it looks for.
    assert _compared_names('a === "lqg" || "mpc" !== b; case \'tvlqr\': ["swingup"].includes(c)',
                           names) == ["lqg", "mpc", "tvlqr", "swingup"]
    scripts = sorted(static.glob("*.js"))
    assert any(p.name == "app.js" for p in scripts)
    for path in scripts:
        assert _compared_names(path.read_text(encoding="utf-8"), names) == [], path.name


def _swingup_session(controller: str) -> Any:
    """A playground session of the cart-pole running *controller*."""
    from equilibrist.web.session import Session
    from equilibrist.web.session_design import Catalogue

    session = Session(Catalogue.default(), "cartpole", seed=3)
    _switch(session, controller)
    return session


def _switch(session: Any, controller: str) -> None:
    from equilibrist.web.session_design import redesign

    settings = session.settings.changed({"controller": controller})
    system = session.prepare(settings)
    session.install(settings, system, *redesign(system, settings))


def _swingup_run(controller: str) -> dict[str, Any]:
    """A playground run of *controller* on the cart-pole, started upright with the pendulum
    1.7 rad away (out of the balance's region, within the track's)."""
    session = _swingup_session(controller)
    session.x[1] = 1.7
    rows: dict[str, list[Any]] = {"x": [], "u": [], "mode": []}
    for _ in range(100):
        session._sample()
        if session.fell is not None:
            break
        rows["x"].append(session.x.copy())
        rows["u"].append(session.u_cmd.copy())
        rows["mode"].append(session.mode)
    out: dict[str, Any] = {k: np.array(v) for k, v in rows.items()}
    out["fell"] = session.fell
    return out


def test_the_playground_runs_a_renamed_swingup_as_the_swingup(twins: dict[str, str]) -> None:
    swingup, renamed = _swingup_run("swingup"), _swingup_run(twins["swingup"])
    # The swing-up's own run: 1.7 rad off is not a fall (only the track ends its run).
    assert swingup["fell"] is None and len(swingup["x"]) == 100
    assert set(swingup["mode"]) <= {"pumping", "balancing"}
    assert renamed["fell"] == swingup["fell"]
    for key in ("x", "u", "mode"):
        np.testing.assert_array_equal(renamed[key], swingup[key])


def _leave(controller: str) -> tuple[np.ndarray, np.ndarray]:
    """The state and the filter's estimate after a switch from *controller* to the LQR with
    the pendulum caught a whole turn away from upright."""
    import math

    session = _swingup_session(controller)
    session.x[1] = 2 * math.pi + 0.03
    _switch(session, "lqr")
    return session.x.copy(), session.loop.filter.estimate()


def test_leaving_a_renamed_swingup_is_leaving_the_swingup(twins: dict[str, str]) -> None:
    x, estimate = _leave("swingup")
    assert abs(x[1] - 0.03) < 1e-12  # the swing-up's: back within half a turn
    x_renamed, estimate_renamed = _leave(twins["swingup"])
    np.testing.assert_array_equal(x_renamed, x)
    np.testing.assert_array_equal(estimate_renamed, estimate)


def test_the_export_writes_a_renamed_lqg_as_the_lqg(twin: str, tmp_path: Path) -> None:
    from equilibrist.numeric.lookup import system_from_key

    system = system_from_key("cartpole")
    texts = {}
    for name in ("lqg", twin):
        request = kinds.ControllerRequest(system=system, rate=None)
        done = kinds.get(name, "export").write_export(request, tmp_path / name,
                                                      precision="double", duration=0.5,
                                                      seed=0, force=False)
        texts[name] = {rel: (done.folder / rel).read_text() for rel in sorted(done.files)
                       if rel.endswith((".h", ".c"))}
    assert texts[twin] == texts["lqg"] and "cartpole_lqg.h" in texts["lqg"]


class _Stop(Exception):
    """Raised by the fake device once the command said what it expects of the device."""


def _hello(controller: str, monkeypatch: pytest.MonkeyPatch) -> Any:
    """The hello the ``hil`` command sends a device for *controller* (through fakes of the
    serial link and of the device: the command stops there)."""
    from equilibrist.cli.main import main
    from equilibrist.hil import link, run

    seen: list[Any] = []

    class Link:
        def __init__(self, port: str, **_: Any) -> None:
            pass

        def __enter__(self) -> Link:
            return self

        def __exit__(self, *exc: object) -> None:
            pass

    def device(link: object, host: Any, **_: Any) -> None:
        seen.append(host)
        raise _Stop

    monkeypatch.setattr(link, "SerialLink", Link)
    monkeypatch.setattr(run, "DeviceController", device)
    with pytest.raises(_Stop):
        main(["hil", "cartpole", "--port", "/dev/null", "--controller", controller,
              "--duration", "0.1"])
    return seen[0]


def test_the_hil_command_expects_of_a_renamed_lqg_the_lqg(twin: str,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    lqg, renamed = _hello("lqg", monkeypatch), _hello(twin, monkeypatch)
    assert renamed == lqg
    assert _hello("lqr", monkeypatch).controller_id != lqg.controller_id  # ids tell kinds apart
