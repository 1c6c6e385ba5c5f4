"""The catalogue's derived models shipped with the package are what derivation gives now.

``numeric/derived/`` holds each catalogue system's generated module, so that
a first use needs neither sympy nor a derivation. Here every system is
derived again (sympy.physics.mechanics, as on first use without the shipped
files) and its generated text compared with the shipped one, character for
character: a change to a system, the mechanics layer or the code
generation that is not followed by ``make derived`` fails here.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from equilibrist.mechanics.definition import Entry
from equilibrist.numeric import cache
from equilibrist.systems import registry

ENTRIES = registry.all_entries()


@pytest.mark.slow
@pytest.mark.parametrize("entry", ENTRIES, ids=[e.spec.key for e in ENTRIES])
def test_the_shipped_derivation_is_todays(entry: Entry) -> None:
    from equilibrist.numeric.package import generated_source

    shipped = cache.packaged_path(entry)
    assert shipped is not None
    assert shipped.is_file(), f"{shipped.name} is missing: run make derived"
    assert shipped.read_text() == generated_source(entry), (
        f"{shipped.name} differs from today's derivation: run make derived")


def test_no_stale_files_are_shipped() -> None:
    wanted = {cache.packaged_path(e) for e in ENTRIES}
    assert set(cache.PACKAGED.glob("*.py.txt")) == wanted


def test_a_first_use_of_a_catalogue_system_needs_no_sympy(tmp_path) -> None:
    """Empty cache: the cart-pole's module comes from the package; sympy is not imported
    until the symbolic model is asked for, and then it is derived."""
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    code = """
import sys
import numpy as np
from equilibrist import get_system
s = get_system("cartpole")
out = np.empty(4)
s.functions.f(np.array([0.0, 0.1, 0.0, 0.0]), np.zeros(1), s.p, out)
print("sympy" in sys.modules)
print(s.symbolic.M.shape)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "EQUILIBRIST_CACHE": str(folder)}, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split("\n")[:2] == ["False", "(2, 2)"]
    assert sorted(p.suffix for p in folder.glob("cartpole_*")) == [".pkl", ".py"]
