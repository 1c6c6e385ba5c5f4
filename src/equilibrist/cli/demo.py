"""``equilibrist demo``: the main job, a tour of the catalogue."""

from __future__ import annotations

import argparse

from equilibrist.errors import NoEquilibriumError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="a tour of the catalogue (what 'make demo' runs)")
    p.add_argument("system", nargs="?", metavar="SYSTEM", help="one system only")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from equilibrist.cli.linearize import render
    from equilibrist.cli.systems import catalogue
    from equilibrist.numeric.system import get_system
    from equilibrist.systems import registry

    names = registry.family_names() if args.system is None else [args.system]
    data = catalogue()
    for name in names:
        registry.lookup_family(name)
        variants = registry.variants(name) or (None,)
        option = registry.variant_option(name)
        for variant in variants:
            settings = {} if variant is None else {option: variant}
            system = get_system(name, **settings)
            print("=" * 72)
            print(f"{system.key}: {data[name]['title']}")
            print("=" * 72)
            try:
                print(render(system, system.linearize()))
            except NoEquilibriumError as exc:
                print(f"(no canonical operating point: {exc})")
            print()
    return 0
