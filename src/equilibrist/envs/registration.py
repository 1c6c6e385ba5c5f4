"""Gymnasium ids for every system and task, read from the catalogue.

The ids come from iterating the system registry and each spec's tasks
(:func:`equilibrist.tasks.spec_task_names`), so a system added to the
catalogue has its environments with nothing else to write. Reading specs
derives no model: registering is cheap.
"""

from __future__ import annotations

import gymnasium as gym

from equilibrist.mechanics.spec import SystemSpec
from equilibrist.systems import registry
from equilibrist.tasks import TASK_NAMES, spec_task_names

NAMESPACE = "equilibrist"
VERSION = 0
_ENTRY = "equilibrist.envs.env:EquilibristEnv"
_VECTOR_ENTRY = "equilibrist.envs.vector:EquilibristVectorEnv"


def _system_id(spec: SystemSpec) -> str:
    # A variant of a family (gyroscope[euler=xyz]) is named gyroscope_xyz.
    return spec.name if spec.variant is None else f"{spec.name}_{spec.variant[1]}"


def _system_arg(spec: SystemSpec) -> str:
    return spec.name


def catalogue_ids() -> dict[str, tuple[SystemSpec, str]]:
    """``{id: (spec, task)}`` for every system with an input and each of its tasks."""
    out: dict[str, tuple[SystemSpec, str]] = {}
    for entry in registry.all_entries():
        spec = entry.spec
        for task in spec_task_names(spec):
            out[f"{NAMESPACE}/{_system_id(spec)}-{task}-v{VERSION}"] = (spec, task)
    return out


def env_ids() -> tuple[str, ...]:
    """Every registered id: the catalogue's, then the per-task ones taking ``system=``."""
    generic = tuple(f"{NAMESPACE}/{task}-v{VERSION}" for task in TASK_NAMES)
    return (*catalogue_ids(), *generic)


def register_all() -> None:
    """Register every id with Gymnasium (again is harmless)."""
    for env_id, (spec, task) in catalogue_ids().items():
        kwargs: dict[str, object] = {"system": _system_arg(spec), "task": task}
        if spec.variant is not None:
            kwargs["params"] = {}
            kwargs["system"] = spec.key
        _register(env_id, kwargs)
    for task in TASK_NAMES:
        _register(f"{NAMESPACE}/{task}-v{VERSION}", {"task": task})


def _register(env_id: str, kwargs: dict[str, object]) -> None:
    if env_id in gym.registry:
        return
    gym.register(id=env_id, entry_point=_ENTRY, vector_entry_point=_VECTOR_ENTRY,
                 kwargs=kwargs, disable_env_checker=False)


__all__ = ["NAMESPACE", "catalogue_ids", "env_ids", "register_all"]
