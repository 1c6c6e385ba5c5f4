"""Designs kept on disk: a later process reads them, bit for bit, without designing again.

A design is a pure function of the system (its definition, parameters and
spec), the arguments, the sources of the control layer and the numpy/scipy
versions; ``design`` keeps each one it makes in the cache folder
(``designs/``) under the hash of all of them, so that a command that runs a
design made before does not redo it (no Riccati equation is solved; the
child counts the calls). A sampled design imports no scipy at all.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

CHILD = """
import json, sys
import equilibrist.control.fixed as fixed
solved = []
dare = fixed.dare
fixed.dare = lambda *a, **k: solved.append(1) or dare(*a, **k)
from equilibrist import get_system
from equilibrist.control.design import design
s = get_system("cartpole", m_p=float(sys.argv[1]))
d = design(s, rate=200.0)
print(json.dumps({"made": bool(solved), "scipy": "scipy" in sys.modules,
                  "K": d.K.tobytes().hex(), "Kf": d.Kf.tobytes().hex(), "notes": list(d.notes)}))
"""


def _run(folder, *args: str) -> dict:
    proc = subprocess.run([sys.executable, "-c", CHILD, *args], capture_output=True, text=True,
                          env={**os.environ, "EQUILIBRIST_CACHE": str(folder)}, check=False)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


def test_a_design_made_before_is_read_not_made_again(tmp_path) -> None:
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    first = _run(folder, "1.0")
    second = _run(folder, "1.0")
    assert first["made"] is True and second["made"] is False
    assert second == {**first, "made": False}  # the same gains, to the bit
    assert first["scipy"] is False  # a sampled design needs no scipy, made or read
    other = _run(folder, "1.2")  # another parameter: designed again, other gains
    assert other["made"] is True and other["K"] != first["K"]


def test_a_damaged_design_file_is_designed_again(tmp_path) -> None:
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    first = _run(folder, "1.0")
    (kept,) = (folder / "designs").glob("*.pkl")
    kept.write_bytes(kept.read_bytes()[:50])
    again = _run(folder, "1.0")
    assert again["made"] is True and again["K"] == first["K"]
    assert _run(folder, "1.0")["made"] is False  # and kept whole again
