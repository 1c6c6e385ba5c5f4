"""Write the catalogue's derived models into the package (``numeric/derived/``).

Run ``python -m equilibrist.numeric.package`` (``make derived``) after a
change to a system, the mechanics layer or the code generation: every
catalogue system (variants included) is derived with sympy and its
generated module written as ``<system>_<key>.py.txt``, the key being
:func:`equilibrist.numeric.cache.model_key` without sympy's version; files
of older keys are removed. A first use of a catalogue system then copies
its module from there into the cache instead of importing sympy and
deriving it (:func:`equilibrist.numeric.cache.load`).
``tests/numeric/test_packaged_models.py`` derives every system again and checks
that the shipped text is what the derivation gives now.
"""

from __future__ import annotations

import sys
from pathlib import Path

from equilibrist.mechanics.definition import Entry
from equilibrist.numeric.cache import PACKAGED, derive, packaged_path
from equilibrist.systems import registry


def generated_source(entry: Entry) -> str:
    """The generated module of *entry*, derived now."""
    from equilibrist.numeric.codegen import generate_source

    model = derive(entry)
    _ = model.A, model.B
    return generate_source(model)


def write(folder: Path = PACKAGED) -> list[Path]:
    """Derive every catalogue system and write its module into *folder*; returns the files."""
    folder.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for entry in registry.all_entries():
        target = packaged_path(entry)
        assert target is not None
        path = folder / target.name
        text = generated_source(entry)
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
        written.append(path)
    for old in folder.glob("*.py.txt"):
        if old not in written:
            old.unlink()
    return written


if __name__ == "__main__":  # pragma: no cover - a maintainer's command
    for path in write():
        print(path.relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path)
    sys.exit(0)
