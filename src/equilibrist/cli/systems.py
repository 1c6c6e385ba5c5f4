"""``equilibrist systems``: the catalogue with states, inputs, outputs and parameters."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, NotRequired, TypedDict

from equilibrist.cli import common
from equilibrist.errors import UsageError

if TYPE_CHECKING:
    from equilibrist.mechanics.spec import SystemSpec


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("systems", help="list every system with its states, inputs and parameters")
    common.add_json(p)
    p.add_argument("--markdown", action="store_true",
                   help="every system's specification page in Markdown (as docs/systems/ holds)")
    p.add_argument("--out", metavar="DIR",
                   help="with --markdown: write one page per system and an index into DIR")
    p.add_argument("--force", action="store_true",
                   help="with --out: replace files of the pages' names that equilibrist did "
                   "not generate")
    p.set_defaults(func=run)


class ParameterEntry(TypedDict):
    """One parameter of :func:`describe`."""

    default: float
    unit: str
    meaning: str
    range: list[float]
    range_text: str


class SystemEntry(TypedDict):
    """One spec as plain data (:func:`describe`); a family's entry in :func:`catalogue`
    adds its variants."""

    name: str
    title: str
    description: str
    variant: dict[str, str] | None
    states: list[str]
    state_units: list[str]
    inputs: list[str]
    input_units: list[str]
    outputs: list[str]
    parameters: dict[str, ParameterEntry]
    operating_point: dict[str, object] | None
    source: str
    variant_option: NotRequired[str]
    variants: NotRequired[dict[str, SystemEntry]]


def describe(spec: SystemSpec) -> SystemEntry:
    """One spec as plain data (the JSON of ``systems`` and of reports)."""
    return {
        "name": spec.name,
        "title": spec.title,
        "description": spec.description,
        "variant": None if spec.variant is None else {spec.variant[0]: spec.variant[1]},
        "states": list(spec.state_names),
        "state_units": [spec.state_unit(s) for s in spec.state_names],
        "inputs": list(spec.input_names),
        "input_units": [i.unit for i in spec.inputs],
        "outputs": list(spec.outputs),
        "parameters": {
            p.name: {
                "default": p.default,
                "unit": p.unit,
                "meaning": p.meaning,
                "range": [p.low, p.high],
                "range_text": p.range_text,
            }
            for p in spec.all_parameters
        },
        "operating_point": None
        if spec.operating_point is None
        else {
            "state": dict(spec.operating_point.state),
            "inputs": dict(spec.operating_point.inputs),
            "solved_for": list(spec.operating_point.free),
        },
        "source": spec.source,
    }


def catalogue() -> dict[str, SystemEntry]:
    """Every system keyed by name; a family lists its variants under ``variants``."""
    from equilibrist.systems import registry

    out: dict[str, SystemEntry] = {}
    for name in registry.family_names():
        option = registry.variant_option(name)
        if option is None:
            out[name] = describe(registry.lookup(name).spec)
            continue
        default = registry.default_variant(name)
        entry = describe(registry.lookup(name, default).spec)
        entry["variant_option"] = option
        entry["variants"] = {v: describe(registry.lookup(name, v).spec) for v in registry.variants(name)}
        out[name] = entry
    return out


def run(args: argparse.Namespace) -> int:
    if args.out is not None and not args.markdown:
        raise UsageError("--out writes the Markdown pages: give --markdown too")
    if args.markdown:
        if args.json:
            raise UsageError("--markdown and --json are two formats: give one")
        from equilibrist import pages

        if args.out is not None:
            if not args.out.strip():
                raise UsageError("--out '': expected the folder to write the pages into")
            written = pages.write_pages(args.out, force=args.force)
            print(f"wrote {len(written)} pages to {args.out}")
            return 0
        texts = pages.pages()
        index = texts.pop(pages.INDEX)
        print("\n".join([index, *texts.values()]), end="")
        return 0
    data = catalogue()
    if args.json:
        common.print_json(data)
        return 0
    for name, entry in data.items():
        specs = list(entry["variants"].values()) if "variants" in entry else [entry]
        print(f"{name}: {entry['title']}")
        for spec in specs:
            tag = ""
            if spec["variant"]:
                (k, v), = spec["variant"].items()
                tag = f"  [{k}={v}]"
            print(f"  states:  {', '.join(spec['states'])}{tag}")
        print(f"  inputs:  {', '.join(entry['inputs']) or '(none)'}")
        print(f"  outputs: {', '.join(entry['outputs']) or '(none)'}")
        rows = [
            [p, f"{v['default']:g}", v["unit"], v["range_text"], v["meaning"]]
            for p, v in entry["parameters"].items()
        ]
        table = common.format_table(["parameter", "default", "unit", "range", "meaning"], rows)
        print("    " + table.replace("\n", "\n    "))
        print()
    return 0
