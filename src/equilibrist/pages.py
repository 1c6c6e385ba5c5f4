"""The specification pages: every system's page, generated from its one definition.

A system's definition (its module's docstring and its
:class:`~equilibrist.mechanics.spec.SystemSpec`) is the only source of what
the docs say about it: coordinates and signs, parameters with units, ranges
and sources, inputs and their limits, the operating point, the sensors and
noise, the design scales and the tasks it offers. ``docs/systems/`` is
written by :func:`write_pages` (``equilibrist systems --markdown --out
docs/systems``), and a test checks that it is current, so the docs cannot
disagree with the code.
"""

from __future__ import annotations

import importlib
import inspect
import math
from pathlib import Path

from equilibrist.mechanics.definition import Entry
from equilibrist.mechanics.spec import SystemSpec
from equilibrist.systems import registry

INDEX = "README.md"
_GENERATED = ("<!-- Generated from the system's definition by `equilibrist systems --markdown "
              "--out docs/systems`; do not edit. -->")


def page_name(spec: SystemSpec) -> str:
    """The file of *spec*'s page (``cartpole.md``, ``gyroscope-euler-xyz.md``)."""
    if spec.variant is None:
        return f"{spec.name}.md"
    return f"{spec.name}-{spec.variant[0]}-{spec.variant[1]}.md"


def _num(v: float | str) -> str:
    if isinstance(v, str):
        return f"`{v}`"
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return f"{v:g}"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines


def _docstring(entry: Entry) -> str:
    try:
        module = importlib.import_module(entry.module)
    except ImportError:
        return ""
    return inspect.cleandoc(module.__doc__ or "")


def _tasks(spec: SystemSpec) -> list[str]:
    from equilibrist import tasks

    offered = tasks.spec_task_names(spec)
    if not offered:
        return ["None: the system has no input (or no operating point) to control."]
    out = []
    region = ", ".join(f"`{k}` in [{_num(lo)}, {_num(hi)}]" for k, (lo, hi) in spec.region.items())
    spread = [n for n in spec.coordinates if n in spec.region]
    out.append(
        f"* `balance`: {tasks.DURATION['balance']:g} s at {spec.control_rate:g} Hz from the "
        "operating point, "
        + (f"{', '.join(f'`{n}`' for n in spread)} drawn uniformly within "
           f"{tasks.BALANCE_SPREAD:g} of its design scale; " if spread else "")
        + (f"fallen outside {region}." if region else "no fall region.")
    )
    if "swingup" in offered and spec.hanging is not None:
        hang = ", ".join(f"`{k}` = {_num(v)}" for k, v in spec.hanging.items())
        names = {p.name for p in spec.all_parameters}
        track = (f"; the cart leaves its track at `|{tasks.TRACK_STATE}| > {tasks.TRACK_PARAMETER}`"
                 if tasks.TRACK_PARAMETER in names and tasks.TRACK_STATE in spec.state_names else
                 "; no fall region")
        out.append(
            f"* `swingup`: {tasks.DURATION['swingup']:g} s at {spec.control_rate:g} Hz from "
            f"hanging at rest ({hang}), each hanging coordinate offset uniformly by up to "
            f"{tasks.SWINGUP_OFFSET:g} rad, ending balanced at the operating point{track}."
        )
    if spec.swingup is not None:
        gains = ", ".join(f"`{k}` = {_num(v)}" for k, v in spec.swingup.gains.items())
        free = "".join(f", catching `{c}` where it is" for c in spec.swingup.free)
        out.append(f"* `--controller swingup`: the `{spec.swingup.law}` energy-pumping law, "
                   f"default gains {gains}{free} (`equilibrist.control.swingup`).")
    return out


def page(entry: Entry) -> str:
    """The Markdown page of one definition."""
    spec = entry.spec
    lines = [_GENERATED, "", f"# {spec.title} (`{spec.key}`)", "", spec.description, ""]
    doc = _docstring(entry)
    if doc:
        lines += ["## As defined", "", "```text", doc, "```", ""]
    lines += ["## States", ""]
    lines += _table(["state", "unit"], [[f"`{s}`", spec.state_unit(s) or "-"] for s in spec.state_names])
    lines += ["", "## Parameters", ""]
    lines += _table(
        ["name", "default", "unit", "range", "meaning", "source"],
        [[f"`{p.name}`", _num(p.default), p.unit or "-", p.range_text, p.meaning, p.note or "-"]
         for p in spec.parameters],
    )
    lines += ["", "## Inputs", ""]
    if spec.inputs:
        lines += _table(["input", "unit", "meaning", "limits"],
                        [[f"`{i.name}`", i.unit, i.meaning, f"[{_num(i.low)}, {_num(i.high)}]"]
                         for i in spec.inputs])
        lines += ["", "The limits are parameters too (`<input>_min`, `<input>_max`), changed "
                  "with `--set`."]
    else:
        lines.append("None.")
    lines += ["", "## Operating point", ""]
    op = spec.operating_point
    if op is None:
        lines.append("None: the system is not balanced at a point.")
    else:
        state = (", ".join(f"`{k}` = {_num(v)}" for k, v in op.state.items()) + " (others 0)"
                 if op.state else "every state 0")
        inputs = ", ".join(f"`{k}` = {_num(v)}" for k, v in op.inputs.items()) or "none fixed"
        lines.append(f"State: {state}. Inputs: {inputs}."
                     + (f" Solved for: {', '.join(f'`{n}`' for n in op.free)}." if op.free else ""))
    lines += ["", "## Sensors and noise", ""]
    lines.append(f"Controller rate: {spec.control_rate:g} Hz.")
    lines.append("")
    if spec.outputs:
        lines += _table(["output", "sensor noise (std per sample)"],
                        [[f"`{o}`", _num(spec.sensor_noise[o]) if o in spec.sensor_noise else "-"]
                         for o in spec.outputs])
    else:
        lines.append("No default outputs.")
    if spec.process_noise:
        lines += ["", "Process noise intensity on each rate (unit of the rate per sqrt(s)): "
                  + ", ".join(f"`{k}` {_num(v)}" for k, v in spec.process_noise.items()) + "."]
    if spec.design_scales:
        lines += ["", "Design scales (Bryson's rule: the largest acceptable deviation): "
                  + ", ".join(f"`{k}` {_num(v)}" for k, v in spec.design_scales.items()) + "."]
    lines += ["", "## Tasks", "", *_tasks(spec)]
    extra = [("Source", [spec.source] if spec.source else []),
             ("Seed slips corrected", list(spec.seed_slips)),
             ("Notes", list(spec.notes)),
             ("Singularity", [spec.singularity] if spec.singularity else [])]
    for title, items in extra:
        if items:
            lines += ["", f"## {title}", "", *[f"* {i}" for i in items]]
    return "\n".join(lines) + "\n"


def catalogue_entries() -> list[Entry]:
    """Every definition of the catalogue, families by variant."""
    out = []
    for name in registry.family_names():
        if registry.variant_option(name) is None:
            out.append(registry.lookup(name))
        else:
            out += [registry.lookup(name, v) for v in registry.variants(name)]
    return out


def pages() -> dict[str, str]:
    """``{file name: Markdown}`` of every catalogue page and the index."""
    entries = catalogue_entries()
    out = {page_name(e.spec): page(e) for e in entries}
    rows = [[f"[`{e.spec.key}`]({page_name(e.spec)})", e.spec.title,
             ", ".join(e.spec.state_names), ", ".join(e.spec.input_names) or "-"] for e in entries]
    out[INDEX] = "\n".join([
        _GENERATED, "", "# The systems", "",
        "Each page is generated from the system's one definition (its module's docstring and "
        "its spec); `equilibrist systems --markdown` prints the same pages, and "
        "`equilibrist systems --json` the same facts for scripts.", "",
        *_table(["system", "title", "states", "inputs"], rows),
    ]) + "\n"
    return out


def write_pages(folder: str | Path, *, force: bool = False) -> list[Path]:
    """Write every page into *folder*; the paths written.

    The folder is created when missing, its parent never (:func:`equilibrist.atomic.check_output`).
    Pages replace the files of their names, other files are left as they are; a file of a
    page's name that equilibrist did not generate (it lacks the pages' first line) is refused
    (:class:`~equilibrist.atomic.OutputError`, naming it), unless *force*.
    """
    from equilibrist.atomic import OutputError, check_output, write_text

    root = check_output(folder, what="--out")
    if root.exists() and not root.is_dir():
        raise OutputError(f"--out {root} is a file: name the folder to write the pages into")
    texts = pages()
    if not force and root.is_dir():
        theirs = sorted(name for name in texts if (root / name).exists()
                        and not _generated(root / name))
        if theirs:
            shown = ", ".join(theirs[:4]) + (f" and {len(theirs) - 4} more" if len(theirs) > 4
                                             else "")
            raise OutputError(f"--out {root} holds {shown}, which equilibrist did not generate: "
                              "writing the pages would replace them; give --force to replace "
                              "them, or name another folder")
    root.mkdir(exist_ok=True)
    return [write_text(root / name, text) for name, text in texts.items()]


def _generated(path: Path) -> bool:
    """Whether *path* is a page equilibrist generated (it begins with the pages' first line)."""
    try:
        with path.open("rb") as fh:
            return fh.read(len(_GENERATED.encode())) == _GENERATED.encode()
    except OSError:
        return False
