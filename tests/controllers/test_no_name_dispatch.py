"""No consumer above the registry asks a kind's name: a kind that is the LQG's record under
another name (``twinlqg``) is, to the playground's session, the export and the ``hil``
command, the LQG itself. Its independent truth is the LQG's own run, library and hello,
which the renamed kind must reproduce to the bit; a consumer that compared the name with
``"lqg"`` would run the open loop, refuse the export or refuse the device instead."""

from __future__ import annotations

import dataclasses
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
