"""``make size``: the embedded budget of an exported library, the same rule in every Makefile.

:func:`size_rules` is the Makefile text every export appends. ``make size`` compiles the
library's sources alone with ``CFLAGS`` and ``-fstack-usage`` into ``size-build/`` and
prints ``code``, ``data`` and ``stack`` in bytes (POSIX sh and awk only): ``size``'s
sums over the objects, and the deepest chain of stack frames from the step functions
along GCC's call graph (``-fcallgraph-info=su``; each group of mutually recursive
functions counted once, calls through a function pointer named and not followed; a
compiler without call graphs gives the largest single frame). docs/export.md
("Embedded budget") says what each figure holds.

:func:`measure` runs the rule in a scratch copy of an export's files and returns the
figures (:class:`Footprint`), or ``None`` where ``make`` or the compiler is missing.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

#: Where ``make size`` compiles (``make clean`` removes it).
BUILD = "size-build"

#: The awk program that sums the stack frames along GCC's call graph (``.ci`` files, VCG).
_CHAIN_AWK = r"""
function strong(v,   k, w, x) {
    idx[v] = ++counter; low[v] = counter; stk[++sp] = v; on[v] = 1;
    for (k = 1; k <= nout[v]; k++) {
        w = out[v, k];
        if (!(w in idx)) { strong(w); if (low[w] < low[v]) low[v] = low[w]; }
        else if (on[w] && idx[w] < low[v]) low[v] = idx[w];
    }
    if (low[v] == idx[v]) {
        nc++;
        do { x = stk[sp--]; on[x] = 0; comp[x] = nc; cw[nc] += frame[x]; cn[nc]++; cm[nc] = cm[nc] " " x; } while (x != v);
    }
}
/^node:/ {
    t = $0; sub(/.*title: "/, "", t); sub(/".*/, "", t);
    if (match($0, /[0-9]+ bytes/)) { f = substr($0, RSTART, RLENGTH); sub(/ bytes/, "", f); frame[t] = f + 0; }
    if (index($0, "dynamic") && !index($0, "bounded")) { unbounded = unbounded " " t; }
}
/^edge:/ {
    s = $0; sub(/.*sourcename: "/, "", s); sub(/".*/, "", s);
    d = $0; sub(/.*targetname: "/, "", d); sub(/".*/, "", d);
    if (!((s, d) in seen)) { seen[s, d] = 1; ne++; src[ne] = s; dst[ne] = d; out[s, ++nout[s]] = d; }
}
END {
    n = split(ENTRY, entry, " ");
    for (i = 1; i <= n; i++) {
        if (!(entry[i] in frame)) { print "size: no stack frame of " entry[i] > "/dev/stderr"; exit 1; }
        if (!(entry[i] in idx)) strong(entry[i]);
    }
    for (e = 1; e <= ne; e++) if ((src[e] in comp) && src[e] == dst[e]) cn[comp[src[e]]]++;
    for (c = 1; c <= nc; c++) {
        deep[c] = cw[c];
        if (cn[c] > 1) print "size: recursive calls (each cycle counted once, " cw[c] " bytes):" cm[c] > "/dev/stderr";
    }
    do { changed = 0;
        for (e = 1; e <= ne; e++) if (src[e] in comp) {
            a = comp[src[e]]; b = comp[dst[e]];
            if (a != b && cw[a] + deep[b] > deep[a]) { deep[a] = cw[a] + deep[b]; changed = 1; }
        }
    } while (changed);
    worst = 0;
    for (i = 1; i <= n; i++) if (deep[comp[entry[i]]] > worst) worst = deep[comp[entry[i]]];
    for (e = 1; e <= ne; e++) if ((src[e] in comp) && dst[e] == "__indirect_call") pointers = pointers " " src[e];
    if (pointers != "") print "size: calls through a pointer not followed, from:" pointers > "/dev/stderr";
    if (unbounded != "") print "size: frames of unbounded dynamic size:" unbounded > "/dev/stderr";
    print "stack", worst;
}
"""

#: The awk program of a compiler without call graphs: the largest frame of a ``.su`` file.
_FRAME_AWK = r"""
{ if ($(NF-1) + 0 > worst) worst = $(NF-1) + 0; }
END {
    print "size: stack is the largest single frame (this compiler writes no call graph)" > "/dev/stderr";
    print "stack", worst + 0;
}
"""


def _make_quote(text: str) -> str:
    """*text* as one line of a Makefile recipe, ``$`` doubled, in single quotes for sh."""
    body = " ".join(line.strip() for line in text.strip().splitlines() if line.strip())
    return "'" + body.replace("$", "$$").replace("'", "'\\''") + "'"


def size_rules(*, sources: str, entry: Sequence[str], cflags: str = "$(CFLAGS)",
               include: str = "-I.") -> str:
    """The Makefile's ``size`` rule (and a ``size-clean``): *sources* the library's C files
    (sh words, globs allowed), *entry* its step functions (the roots of the stack's chain),
    *cflags* and *include* the compile flags."""
    chain = _make_quote(_CHAIN_AWK)
    frame = _make_quote(_FRAME_AWK)
    return "\n".join([
        "",
        "# 'make size': the library alone (not the test program or the examples) compiled",
        f"# with CFLAGS and -fstack-usage into {BUILD}/; prints 'code N' (text + data: flash),",
        "# 'data N' (data + bss: static RAM) and 'stack N' (the deepest chain of frames from",
        "# the step functions, from GCC's -fcallgraph-info; a compiler without it gives the",
        "# largest frame). SIZE: the binutils size program (a cross-compiler's for a device).",
        "SIZE ?= size",
        f"SIZE_SRC = {sources}",
        f"SIZE_ENTRY = {' '.join(entry)}",
        "",
        "size:",
        f"\t@rm -rf {BUILD} && mkdir {BUILD}",
        f"\t@echo 'int size_probe;' > {BUILD}/probe.c; \\",
        f"\tif $(CC) -fcallgraph-info=su -c {BUILD}/probe.c -o {BUILD}/probe.o 2>/dev/null; \\",
        "\tthen cg=-fcallgraph-info=su; else cg=; fi; \\",
        f"\trm -f {BUILD}/probe.*; \\",
        "\tfor f in $(SIZE_SRC); do \\",
        "\t  b=`basename $$f .c`; \\",
        f"\t  $(CC) {cflags} {include} -fstack-usage $$cg -c $$f -o {BUILD}/$$b.o || exit 1; \\",
        "\tdone",
        f"\t@$(SIZE) {BUILD}/*.o | awk 'NR > 1 {{ t += $$1 + $$2; d += $$2 + $$3 }} "
        "END { print \"code\", t; print \"data\", d }'",
        f"\t@if ls {BUILD}/*.ci >/dev/null 2>&1; then \\",
        f"\t  cat {BUILD}/*.ci | awk -v ENTRY='$(SIZE_ENTRY)' {chain}; \\",
        f"\telse cat {BUILD}/*.su | awk {frame}; fi",
        "",
        "size-clean:",
        f"\trm -rf {BUILD}",
        "",
        ".PHONY: size size-clean",
        "",
    ])


@dataclass(frozen=True)
class Footprint:
    """What ``make size`` printed [bytes]."""

    code: int
    data: int
    stack: int

    def as_dict(self) -> dict[str, int]:
        return {"code": self.code, "data": self.data, "stack": self.stack}


def parse(text: str) -> Footprint:
    """The three figures of ``make size``'s output (other lines ignored)."""
    found = dict(re.findall(r"^(code|data|stack) (\d+)\s*$", text, flags=re.M))
    missing = {"code", "data", "stack"} - set(found)
    if missing:
        raise ValueError(f"'make size' printed no {', '.join(sorted(missing))}: {text.strip()!r}")
    return Footprint(code=int(found["code"]), data=int(found["data"]), stack=int(found["stack"]))


def run_size(folder: str | os.PathLike[str], env: Mapping[str, str] | None = None) -> Footprint:
    """``make -C folder size``, parsed (:class:`subprocess.CalledProcessError` if it fails)."""
    proc = subprocess.run(["make", "-s", "--no-print-directory", "-C", str(folder), "size"],
                          capture_output=True, text=True, check=True,
                          env=dict(env) if env is not None else None)
    return parse(proc.stdout)


def measure(files: Mapping[str, str]) -> tuple[Footprint | None, str]:
    """``make size`` of an export's *files* (relative path -> text) in a scratch folder:
    the figures and ``""``, or ``None`` and why not (no ``make``, no compiler, a failure).
    ``CC`` from the environment, else ``cc``."""
    if shutil.which("make") is None:
        return None, "make is not installed"
    cc = os.environ.get("CC", "cc").split()
    if not cc or shutil.which(cc[0]) is None:
        return None, f"no C compiler ({' '.join(cc) or 'cc'})"
    env = {k: v for k, v in os.environ.items() if not k.startswith(("MAKE", "MFLAGS"))}
    with tempfile.TemporaryDirectory(prefix="equilibrist-size-") as tmp:
        for rel, text in files.items():
            path = Path(tmp) / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
        try:
            return run_size(tmp, env), ""
        except (subprocess.CalledProcessError, ValueError, OSError) as exc:
            detail = getattr(exc, "stderr", "") or str(exc)
            return None, "make size failed: " + " | ".join(str(detail).strip().splitlines()[:3])


def readme_lines(footprint: Footprint | None, why: str = "", *, heap: str = "none") -> list[str]:
    """The README.txt's lines of the footprint (``make size``)."""
    if footprint is None:
        return ["Footprint: not measured at export (" + why + "); run 'make size'.", ""]
    return [
        "Footprint ('make size' at export: the library alone, this machine's compiler, -O2):",
        f"  code   {footprint.code:>8} bytes  flash: instructions, constants, initial data",
        f"  data   {footprint.data:>8} bytes  RAM: static data (data + bss)",
        f"  stack  {footprint.stack:>8} bytes  deepest chain of frames from the step functions",
        f"  heap   {heap}",
        "",
    ]


def controller_readme(title: str, files: Mapping[str, str], *, footprint: Footprint | None,
                      why: str = "", heap: str = "none", notes: Sequence[str] = ()) -> str:
    """README.txt of a controller's export (the MPC's, the nonlinear controllers'): what it
    is, the make targets, its files, its footprint (:func:`readme_lines`) and *notes*."""
    lines = [
        title, "",
        "  make check     run the test program (exit status 0 when the C code matches)",
        "  make size      the library's code, static data and stack [bytes]",
        "  make hil-host  the controller as a hardware-in-the-loop host program",
        "",
    ]
    listing = {**files, "README.txt": "this list"}
    width = max(len(f) for f in listing)
    lines += [f"  {fname:<{width}}  {what}" for fname, what in listing.items()]
    lines += ["", *readme_lines(footprint, why, heap=heap), *notes]
    return "\n".join(lines).rstrip("\n") + "\n"


__all__ = ["BUILD", "Footprint", "controller_readme", "measure", "parse", "readme_lines",
           "run_size", "size_rules"]
