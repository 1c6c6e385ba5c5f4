"""The packed linear controller's layout, read by the simulation core, Python and C: the header
and blocks of a packed :class:`~equilibrist.control.controller.LinearController`, the
generic loop (:data:`LINEAR_SOURCE`), its unrolled form for small patterns, and that source
run as plain Python. It is Python shared with C, and imports nothing of ``control``: the
controller packs its vector by it, the core and the exports translate its sources.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

# -- the packed linear controller: one layout, read by the core, Python and C -------------------
#: Header slots of a packed :class:`LinearController` (name -> index): the sizes, then
#: the offset of each block in the vector.
LINEAR_HEADER: tuple[str, ...] = (
    "nz", "ny", "nr", "m", "n",
    "Ac", "By", "Br", "Bu", "Cc", "Dy", "Dr", "Ez", "Ey", "u_op", "y_op", "r_op", "x_op",
)
#: The blocks of a packed controller after the header, with their shapes in sizes.
LINEAR_BLOCKS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("Ac", ("nz", "nz")), ("By", ("nz", "ny")), ("Br", ("nz", "nr")), ("Bu", ("nz", "m")),
    ("Cc", ("m", "nz")), ("Dy", ("m", "ny")), ("Dr", ("m", "nr")),
    ("Ez", ("n", "nz")), ("Ey", ("n", "ny")),
    ("u_op", ("m",)), ("y_op", ("ny",)), ("r_op", ("nr",)), ("x_op", ("n",)),
)


@dataclass(frozen=True)
class Layout:
    """The layout of a controller's parameter vector, one object for the packing and the source.

    The vector is a header (the scalar *slots*, then the offset of each block), then the
    *blocks* in order, each of the shape its dims say (names of slots, or integers). The
    source reads the layout through :meth:`constants` (``PREFIX_SLOT``: a slot's index,
    ``PREFIX_O_BLOCK``: the index of the slot holding a block's offset), so the offsets a
    controller's source reads are the ones :meth:`pack` wrote; with *fixed* sizes
    (:meth:`fixed_constants`) a block's offset is a constant of the source itself. This is
    the linear controller's scheme (:data:`LINEAR_HEADER`, :data:`LINEAR_BLOCKS`) for any
    controller.
    """

    prefix: str
    slots: tuple[str, ...]
    blocks: tuple[tuple[str, tuple[str | int, ...]], ...]

    @property
    def header(self) -> tuple[str, ...]:
        return self.slots + tuple(f"o_{name}" for name, _ in self.blocks)

    def constants(self) -> dict[str, int]:
        """The header's indices as the source's constants (``TV_N``, ``TV_O_GAINS``...)."""
        return {f"{self.prefix}_{name.upper()}": i for i, name in enumerate(self.header)}

    def offsets(self, sizes: Mapping[str, float]) -> dict[str, int]:
        """Each block's offset (and ``"end"``) for the slots' values *sizes*."""
        out, at = {}, len(self.header)
        for name, dims in self.blocks:
            out[name] = at
            at += math.prod(self._dim(d, sizes) for d in dims)
        out["end"] = at
        return out

    def fixed_constants(self, sizes: Mapping[str, float]) -> dict[str, int]:
        """:meth:`constants`, and each block's offset for *sizes* as ``PREFIX_BLOCK``."""
        out = self.constants()
        out.update({f"{self.prefix}_{name.upper()}": at for name, at in self.offsets(sizes).items()})
        return out

    def source(self, sizes: Mapping[str, float] | None = None) -> str:
        """The constants as the source's first lines."""
        consts = self.constants() if sizes is None else self.fixed_constants(sizes)
        return "\n".join(f"{k} = {v}" for k, v in consts.items()) + "\n"

    def pack(self, slots: Mapping[str, float], blocks: Mapping[str, object]) -> np.ndarray:
        """The vector: *slots* by name, every block of *blocks* (flattened, checked against
        its shape)."""
        offsets = self.offsets(slots)
        out = np.zeros(offsets["end"])
        for i, name in enumerate(self.slots):
            out[i] = float(slots[name])
        for j, (name, dims) in enumerate(self.blocks):
            values = np.asarray(blocks[name], dtype=float).reshape(-1)
            size = math.prod(self._dim(d, slots) for d in dims)
            if values.size != size:
                raise ValueError(f"block {name} has {values.size} values, expected {size}")
            out[len(self.slots) + j] = offsets[name]
            out[offsets[name]:offsets[name] + size] = values
        return out

    def read(self, p: np.ndarray, name: str) -> np.ndarray:
        """Block *name* of the packed vector *p*, in its shape."""
        p = np.asarray(p, dtype=float)
        sizes = {s: float(p[i]) for i, s in enumerate(self.slots)}
        dims = dict(self.blocks)[name]
        shape = tuple(self._dim(d, sizes) for d in dims)
        at = int(p[self.header.index(f"o_{name}")])
        return p[at:at + math.prod(shape)].reshape(shape)

    @staticmethod
    def _dim(d: str | int, sizes: Mapping[str, float]) -> int:
        return d if isinstance(d, int) else int(sizes[d])


def linear_constants() -> dict[str, int]:
    """``{"_LIN_NZ": 0, ..., "_LIN_X_OP": 17}``: the header slots as source constants."""
    return {f"_LIN_{name.upper()}": i for i, name in enumerate(LINEAR_HEADER)}


def linear_sizes(p: np.ndarray) -> dict[str, int] | None:
    """The sizes ``nz, ny, nr, m, n`` in the header of the packed vector *p* (None if it has none)."""
    if p.shape[0] < len(LINEAR_HEADER):
        return None
    return {key: int(p[LINEAR_HEADER.index(key)]) for key in ("nz", "ny", "nr", "m", "n")}


def linear_layout_source(sizes: Mapping[str, int] | None = None) -> str:
    """Source of ``linear_layout(p)``: the sizes and block offsets :data:`LINEAR_SOURCE` reads.

    It returns the :data:`LINEAR_HEADER` slots in order. Without *sizes*
    they are read from the header of *p* at every call (any packed
    controller); with *sizes* (``nz, ny, nr, m, n``) the function returns
    them, and the offsets they imply, as literals, so that the compiled
    loops of the linear library have fixed trip counts and constant
    indices (the C compiler unrolls them). Such a source serves only
    vectors of exactly those sizes; the sums and their order are the same
    either way, so the results are too, bit for bit.
    """
    head = 'def linear_layout(p):\n    """Sizes and offsets of the packed controller *p*."""\n'
    if sizes is None:
        items = [f"int(p[_LIN_{name.upper()}])" for name in LINEAR_HEADER]
        return head + "    return (" + ", ".join(items) + ")\n"
    values = {key: int(sizes[key]) for key in ("nz", "ny", "nr", "m", "n")}
    offset = len(LINEAR_HEADER)
    for name, dims in LINEAR_BLOCKS:
        values[name] = offset
        offset += math.prod(values[d] for d in dims)
    return head + "    return (" + ", ".join(str(values[name]) for name in LINEAR_HEADER) + ")\n"


#: The most multiply-adds a linear controller may have for :func:`linear_unrolled_source`
#: to write its sums out term by term (larger ones run the loops of :data:`LINEAR_SOURCE`).
UNROLL_LIMIT = 1024

# Per function: the output (its offset block, its row count) and the terms of each row,
# ``(matrix, input)`` in the order of the sums of LINEAR_SOURCE (z, then y, r, u).
_UNROLLED: tuple[tuple[str, str, str, str, tuple[tuple[str, str], ...]], ...] = (
    ("linear_output", "t, z, y, r, p, u_out", "u_out", "m",
     (("Cc", "z"), ("Dy", "y"), ("Dr", "r"))),
    ("linear_update", "t, z, y, r, u_applied, p, z_out", "z_out", "nz",
     (("Ac", "z"), ("By", "y"), ("Br", "r"), ("Bu", "u"))),
    ("linear_estimate", "t, z, y, r, p, x_out", "x_out", "n",
     (("Ez", "z"), ("Ey", "y"))),
)
_UNROLLED_BASE = {"u_out": "u_op", "z_out": None, "x_out": "x_op"}
_INPUTS = {"z": ("nz", None, "z"), "y": ("ny", "y_op", "y"), "r": ("nr", "r_op", "r"),
           "u": ("m", "u_op", "u_applied")}


def linear_pattern(p: np.ndarray) -> bytes | None:
    """What :func:`linear_unrolled_source` specializes to in the packed vector *p*.

    The sizes, then one byte per matrix coefficient (every block from ``Ac``
    to ``Ey``, in order): 0 for an exact zero, 1 for an exact one, 2 for any
    other number. None for a vector without a header, or one too large to
    be written out term by term (:data:`UNROLL_LIMIT`).
    """
    sizes = linear_sizes(p)
    if sizes is None:
        return None
    start = int(p[LINEAR_HEADER.index("Ac")])
    end = int(p[LINEAR_HEADER.index("u_op")])
    if end - start > UNROLL_LIMIT:
        return None
    block = p[start:end]
    codes = np.where(block == 0.0, 0, np.where(block == 1.0, 1, 2)).astype(np.uint8)
    head = np.array([sizes[k] for k in ("nz", "ny", "nr", "m", "n")], dtype=np.int64)
    return head.tobytes() + codes.tobytes()


def linear_unrolled_source(pattern: bytes) -> str:
    """The linear library (``linear_layout``, ``linear_output``, ``linear_update``,
    ``linear_estimate``) written out for the vectors of one :func:`linear_pattern`.

    Each sum is written term by term with the offsets as literals, each
    input deviation (``y[j] - y_op[j]``...) is computed once, and every
    result is stored after all are computed. Terms whose coefficient is an
    exact zero are left out and an exact one multiplies nothing: with
    finite inputs that gives the very bits of :data:`LINEAR_SOURCE`'s sums
    (the sum starts at ``+0.0`` and is never ``-0.0``, so adding ``+-0.0``
    changes nothing, and ``1.0 * d`` is ``d``). Where an input that such a
    term would multiply is not finite (``0 * inf`` is NaN), the function
    takes the full sums instead, so the results are the same in every case.
    The source serves only vectors of that pattern (their sizes, and
    zeros and ones where the pattern has them).
    """
    head = np.frombuffer(pattern[:40], dtype=np.int64)
    sizes = dict(zip(("nz", "ny", "nr", "m", "n"), (int(v) for v in head), strict=True))
    codes = pattern[40:]
    offsets = dict(sizes)
    offset = len(LINEAR_HEADER)
    for name, dims in LINEAR_BLOCKS:
        offsets[name] = offset
        offset += math.prod(sizes[d] for d in dims)
    base = offsets["Ac"]
    lines = [linear_layout_source(sizes)]

    def deviation(kind: str, j: int) -> str:
        _size, op, arg = _INPUTS[kind]
        return f"{arg}[{j}]" if op is None else f"{arg}[{j}] - p[{offsets[op] + j}]"

    def sums(rows: int, terms: tuple[tuple[str, str], ...], skip: bool, indent: str) -> list[str]:
        out = []
        for i in range(rows):
            expr = None
            for matrix, kind in terms:
                width = sizes[_INPUTS[kind][0]]
                for j in range(width):
                    at = offsets[matrix] + i * width + j
                    code = codes[at - base]
                    if skip and code == 0:
                        continue
                    term = f"d_{kind}{j}" if skip and code == 1 else f"p[{at}] * d_{kind}{j}"
                    expr = f"0.0 + {term}" if expr is None else f"v{i} + {term}"
                    out.append(f"{indent}v{i} = {expr}")
            if expr is None:
                out.append(f"{indent}v{i} = 0.0")
        return out

    for name, args, result, rows_key, terms in _UNROLLED:
        rows = sizes[rows_key]
        used = [(kind, j) for _m, kind in terms for j in range(sizes[_INPUTS[kind][0]])]
        lines.append(f"\n\ndef {name}({args}):")
        lines.append('    """The linear library\'s sums, written out for one pattern of vectors."""')
        lines += [f"    d_{kind}{j} = {deviation(kind, j)}" for kind, j in used]
        # Inputs that multiply an exact zero somewhere: their finiteness decides the path.
        zeroed = sorted({(kind, j) for matrix, kind in terms
                         for i in range(rows) for j in range(sizes[_INPUTS[kind][0]])
                         if codes[offsets[matrix] + i * sizes[_INPUTS[kind][0]] + j - base] == 0})
        op = _UNROLLED_BASE[result]
        stores = [f"{result}[{i}] = " + (f"p[{offsets[op] + i}] + v{i}" if op else f"v{i}")
                  for i in range(rows)]
        if zeroed:
            finite = " + ".join(f"0.0 * d_{kind}{j}" for kind, j in zeroed)
            lines.append(f"    if {finite} == 0.0:")
            lines += sums(rows, terms, True, "        ")
            lines += [f"        {s}" for s in stores]
            lines.append("    else:")
            lines += sums(rows, terms, False, "        ")
            lines += [f"        {s}" for s in stores]
        else:
            lines += sums(rows, terms, False, "    ")
            lines += [f"    {s}" for s in stores]
        if not used and not rows:
            lines.append("    pass")
    return "\n".join(lines) + "\n"


#: The compiled linear controller: plain Python translated to C into every
#: simulation core, and that :class:`LinearController` runs as is in Python.
#: Every sum runs in one fixed order (z, then y, then r, then u), the order the
#: exported C code repeats. It reads its sizes and block offsets through
#: ``linear_layout`` (:func:`linear_layout_source`), defined beside it: from the
#: vector's header in Python and in a nonlinear controller's core, as literals
#: in the core of one linear controller.
LINEAR_SOURCE = '''
def linear_output(t, z, y, r, p, u_out):
    """u = u_op + Cc z + Dy (y - y_op) + Dr (r - r_op) (absolute u, not saturated)."""
    (nz, ny, nr, m, n, o_ac, o_by, o_br, o_bu, o_cc, o_dy, o_dr, o_ez, o_ey,
     o_u0, o_y0, o_r0, o_x0) = linear_layout(p)
    for i in range(m):
        v = 0.0
        for j in range(nz):
            v += p[o_cc + i * nz + j] * z[j]
        for j in range(ny):
            v += p[o_dy + i * ny + j] * (y[j] - p[o_y0 + j])
        for j in range(nr):
            v += p[o_dr + i * nr + j] * (r[j] - p[o_r0 + j])
        u_out[i] = p[o_u0 + i] + v


def linear_update(t, z, y, r, u_applied, p, z_out):
    """z_out = Ac z + By (y - y_op) + Br (r - r_op) + Bu (u_applied - u_op)."""
    (nz, ny, nr, m, n, o_ac, o_by, o_br, o_bu, o_cc, o_dy, o_dr, o_ez, o_ey,
     o_u0, o_y0, o_r0, o_x0) = linear_layout(p)
    for i in range(nz):
        v = 0.0
        for j in range(nz):
            v += p[o_ac + i * nz + j] * z[j]
        for j in range(ny):
            v += p[o_by + i * ny + j] * (y[j] - p[o_y0 + j])
        for j in range(nr):
            v += p[o_br + i * nr + j] * (r[j] - p[o_r0 + j])
        for j in range(m):
            v += p[o_bu + i * m + j] * (u_applied[j] - p[o_u0 + j])
        z_out[i] = v


def linear_estimate(t, z, y, r, p, x_out):
    """x_out = x_op + Ez z + Ey (y - y_op): the state estimate behind the command."""
    (nz, ny, nr, m, n, o_ac, o_by, o_br, o_bu, o_cc, o_dy, o_dr, o_ez, o_ey,
     o_u0, o_y0, o_r0, o_x0) = linear_layout(p)
    for i in range(n):
        v = 0.0
        for j in range(nz):
            v += p[o_ez + i * nz + j] * z[j]
        for j in range(ny):
            v += p[o_ey + i * ny + j] * (y[j] - p[o_y0 + j])
        x_out[i] = p[o_x0 + i] + v
'''

#: Names the linear library defines (a nonlinear controller's source may call them).
LINEAR_FUNCTIONS = ("linear_output", "linear_update", "linear_estimate")

_PY_LINEAR: dict[str, Callable[..., None]] = {}
#: The library written out per pattern (:func:`python_linear`), as Python.
_PY_UNROLLED: dict[bytes, dict[str, Callable[..., None]]] = {}


def _exec_linear(source: str) -> dict[str, Callable[..., None]]:
    namespace: dict[str, Any] = {"math": math, "np": np, **linear_constants()}
    exec(compile(source, "<equilibrist linear controller>", "exec"), namespace)
    return {name: namespace[name] for name in LINEAR_FUNCTIONS}


def _python_linear() -> dict[str, Callable[..., None]]:
    """:data:`LINEAR_SOURCE` executed as plain Python (the reference the core is checked on)."""
    if not _PY_LINEAR:
        _PY_LINEAR.update(_exec_linear(linear_layout_source() + LINEAR_SOURCE))
    return _PY_LINEAR


def python_linear(p: np.ndarray) -> dict[str, Callable[..., None]]:
    """The linear library for the packed vector *p* as plain Python: written out for its
    pattern (:func:`linear_unrolled_source`, the core's own form of it), or the generic loops
    where it is too large to write out; the same sums either way. Fast on lists."""
    pattern = linear_pattern(p)
    if pattern is None:
        return _python_linear()
    if pattern not in _PY_UNROLLED:
        if len(_PY_UNROLLED) > 64:
            _PY_UNROLLED.clear()
        _PY_UNROLLED[pattern] = _exec_linear(linear_unrolled_source(pattern))
    return _PY_UNROLLED[pattern]
