"""The ending every generated controller library shares: recorded vectors, a test program, ``make check``.

:func:`check_files` writes, for a library ``<name>.h`` / ``<name>.c``:

``<name>_vectors.h``
    ``N_VECTORS``, any further ``#define`` (tolerances) and one
    ``static const double vec_<key>[N_VECTORS][columns]`` per recorded
    array (one row per sample).
``test_<name>.c``
    ``main()`` around the caller's loop over the vectors (it returns
    non-zero when a sample is off), with ``<math.h>``, ``<stdio.h>``, the
    library's header and the vectors included.
``Makefile``
    ``make check`` builds the test program from it and the library's
    sources and runs it; ``make size`` prints the library's code, static
    data and stack (:func:`equilibrist.native.size.size_rules`, the rule
    every export's Makefile shares); ``make clean``.

Used by the nonlinear controllers' and the MPC's exports.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from equilibrist.native.size import BUILD, size_rules


def c_rows(values: np.ndarray) -> str:
    """The rows of a 2-D array as C initializers, ``{a, b},\\n    {c, d}`` (``repr`` digits)."""
    mat = np.asarray(values, dtype=float)
    return ",\n    ".join("{" + ", ".join(repr(float(v)) for v in row) + "}" for row in mat)


def vectors_header(arrays: Mapping[str, np.ndarray], *, comment: str,
                   defines: Mapping[str, object] | None = None) -> str:
    """``<name>_vectors.h``: ``N_VECTORS``, *defines* and ``vec_<key>`` per array of *arrays*."""
    counts = {len(np.asarray(a)) for a in arrays.values()}
    if len(counts) != 1:
        raise ValueError(f"recorded arrays of different lengths: {sorted(counts)}")
    k = counts.pop()
    lines = [f"/* {comment} */", f"#define N_VECTORS {k}"]
    lines += [f"#define {key} {value!r}" for key, value in (defines or {}).items()]
    for key, values in arrays.items():
        mat = np.asarray(values, dtype=float).reshape(k, -1)
        cols = max(1, mat.shape[1])
        lines.append(f"static const double vec_{key}[{k}][{cols}] = {{\n    {c_rows(mat)}\n}};")
    return "\n".join(lines) + "\n"


def check_files(
    name: str,
    arrays: Mapping[str, np.ndarray],
    *,
    comment: str,
    program: str,
    what: str,
    sources: Sequence[str] = (),
    cflags: str = "-std=c99 -O2 -ffp-contract=off",
    include: Sequence[str] = (),
    defines: Mapping[str, object] | None = None,
    entry: Sequence[str] | None = None,
) -> dict[str, str]:
    """``<name>_vectors.h``, ``test_<name>.c`` and a ``Makefile`` whose ``make check`` runs them.

    Parameters
    ----------
    name:
        The library's name (``<name>.h``, ``<name>.c``).
    arrays:
        Recorded vectors, ``key -> (samples, columns)``, written as ``vec_<key>``.
    comment:
        First line of the vectors' header (what was recorded).
    program:
        The body of the test program's ``main()`` (C, indented), returning
        non-zero on failure.
    what:
        What the test program checks (its first comment).
    sources:
        C sources besides ``<name>.c`` (Makefile syntax, e.g. ``$(wildcard daqp/src/*.c)``).
    cflags:
        The default ``CFLAGS`` (keep ``-ffp-contract=off``: no fused multiply-add, the
        simulation's bits on every host).
    include:
        Include folders (``-I``) beyond the export's own.
    defines:
        ``#define`` in the vectors' header (tolerances).
    entry:
        The library's step functions, where ``make size`` starts the stack's chain
        (default ``<name>_output`` and ``<name>_update``).
    """
    prog = (
        f"/* test_{name}.c: {what} */\n"
        "#include <math.h>\n#include <stdio.h>\n"
        f'#include "{name}.h"\n#include "{name}_vectors.h"\n\n'
        f"int main(void)\n{{\n{program.rstrip()}\n}}\n"
    )
    inc = " ".join(f"-I{d}" for d in (*include, "."))
    src = " ".join((*sources, f"{name}.c"))
    make = (
        f"CC ?= cc\nCFLAGS ?= {cflags}\nINC = {inc}\nSRC = {src}\n\n"
        f"test_{name}: test_{name}.c $(SRC) {name}.h {name}_vectors.h\n"
        f"\t$(CC) $(CFLAGS) $(INC) -o $@ test_{name}.c $(SRC) -lm\n\n"
        f"check: test_{name}\n\t./test_{name}\n\n"
        f"clean:\n\trm -f test_{name}\n\trm -rf {BUILD}\n\n.PHONY: check clean\n"
    ) + size_rules(sources="$(SRC)", include="$(INC)",
                   entry=entry or (f"{name}_output", f"{name}_update"))
    return {
        f"{name}_vectors.h": vectors_header(arrays, comment=comment, defines=defines),
        f"test_{name}.c": prog,
        "Makefile": make,
    }


__all__ = ["c_rows", "check_files", "vectors_header"]
