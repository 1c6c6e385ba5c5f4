"""A module of one's own, installed in a temporary folder and found through its entry point
(the way a package installed by pip is): what the "one file" tests add, and the
environment of the processes that find it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def install(folder: Path, module: str, source: str, group: str, name: str,
            target: str | None = None) -> dict[str, str]:
    """Write *module*.py with *source* into *folder* beside a distribution's metadata whose
    entry point *name* of *group* names *target* (default: the module); return the
    environment of a process that sees it (PYTHONPATH)."""
    (folder / f"{module}.py").write_text(source)
    info = folder / f"{module}-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {module.replace('_', '-')}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(f"[{group}]\n{name} = {target or module}\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(folder), env.get("PYTHONPATH")]))
    return env


def cli(env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    """``equilibrist ARGS`` in a process with *env*."""
    return subprocess.run([sys.executable, "-m", "equilibrist.cli.main", *args], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
