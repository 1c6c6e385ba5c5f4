"""What a study is: the quantities varied, the points, the runs per point.

A study is a grid (every combination of the varied quantities' values) or a random sample
(``sample = N`` points drawn within the ranges) over physical parameters, ``rate``,
``q.<state>`` and ``r.<input>`` (Bryson scales), ``controller``, ``noise`` and ``delay``,
times ``runs`` closed-loop runs per point; the quantities and the values' forms are in
``docs/studies.md``.

Determinism: everything random in point ``i`` comes from
``numpy.random.SeedSequence(seed, spawn_key=(i, k))`` (``k = 0`` the
point's values in a random sample, ``1`` its initial states and spread,
``2, b`` the noise of its ``b``-th batch of ``batch_size`` runs, ``3`` the
region-of-attraction grid's noise): never from the worker, the chunk or the
order in which points finish.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.errors import nearest
from equilibrist.study.axes import _axis, _number, _ranges, _whole
from equilibrist.study.choice import check_builds, check_choice, is_file, parse_choice
from equilibrist.study.record import (
    BATCH_CELLS,
    DESIGN_FOR,
    MAX_POINTS,
    MAX_RUN_SAMPLES,
    METRICS,
    Axis,
    Study,
    StudyError,
    controllers,
)

if TYPE_CHECKING:
    from equilibrist.numeric.system import System


def make_study(
    system: str,
    *,
    vary: Mapping[str, object] | Sequence[tuple[str, object]] = (),
    sample: int | None = None,
    runs: int = 100,
    duration: float = 5.0,
    x0: Mapping[str, object] | None = None,
    spread: Mapping[str, object] | None = None,
    settings: Mapping[str, object] | None = None,
    seed: int = 0,
    controller: str = "lqg",
    noise: float | str = 1.0,
    delay: bool = False,
    rate: float | None = None,
    design_for: str = "point",
    metrics: str = "full",
    roa: Mapping[str, object] | None = None,
    batch_size: int | None = None,
    controller_options: Mapping[str, object] | None = None,
) -> Study:
    """A validated :class:`Study`; every problem is collected and raised at once
    (:class:`StudyError`).

    *vary* maps each varied quantity to its values (text as on the command line, a list, or
    ``{low, high, n, log}``); *sample* draws that many random points instead of the grid.
    *x0* gives the initial states' absolute ranges (the other states at the operating
    point), *spread* each parameter's relative spread around the point's value.
    *controller*, *noise* (a scale, or ``on``/``off``), *delay* and *rate* (default: the
    rig's) are the values of the quantities not varied. *design_for* ``"nominal"`` keeps one
    nominal design at every point instead of designing for each point's parameters: the
    design of the system with *settings*, whose value of a parameter also varied is the
    nominal one (the points run the varied values).
    *metrics* ``"full"`` adds settling times and the quadratic cost. *roa* is a grid of
    initial states run per point (``roa_fraction``, the share caught). *batch_size* is the
    runs per compiled batch (default: about 32 MB of trajectories); the noise seeds follow
    it. *controller_options* are the kinds' own options by key (``trajectory``,
    ``horizon``...), checked as the command line checks them; a file is recorded as an
    absolute path.
    """
    fixed, sysm = _study_system(system, settings)
    spec = sysm.spec
    problems: list[str] = []
    sampled = sample is not None
    n_sample = None
    if sampled:
        n_sample = _whole(sample, "--sample random:N", problems)
    axes = _axes(sysm, vary, sampled=sampled, problems=problems)
    n_runs = _whole(runs, "--runs", problems)
    dur = _number(duration, "--duration", problems)
    if dur is not None and dur <= 0:
        problems.append(f"--duration must be positive, got {dur:g}")
    seed_v = _whole(seed, "--seed", problems, minimum=0)
    chosen = check_choice(sysm, controller, "--controller", problems)
    choices = [parse_choice(str(v)) for a in axes if a.kind == "controller" for v in a.values]
    kinds_used = [c.kind for c in (chosen, *choices) if c is not None]
    options_v = _controller_options(controller_options or {}, kinds_used, problems)
    noise_v = _noise_scale(noise, problems)
    rate_v = float(spec.control_rate) if rate is None else _number(rate, "--rate", problems)
    if rate_v is not None and rate_v <= 0:
        problems.append(f"--rate must be positive, got {rate_v:g}")
    if design_for not in DESIGN_FOR:
        problems.append(f"--design-for {design_for!r}: expected point or nominal")
    if metrics not in METRICS:
        problems.append(f"--metrics {metrics!r}: expected full or basic")
    x0_r = _ranges(sysm, x0 or {}, "--x0", problems, counted=False)
    roa_r = _ranges(sysm, roa or {}, "--roa", problems, counted=True)
    spread_v = _spreads(sysm, spread or {}, problems)
    if dur is not None and rate_v is not None and dur > 0:
        _check_run_samples(dur, _rates(rate_v, axes), problems)
    if problems:
        raise StudyError("; ".join(problems))
    assert chosen is not None and rate_v is not None
    axis = [("--vary controller", c) for c in choices]
    for what, choice in ([] if axis else [("--controller", chosen)]) + axis:
        check_builds(sysm, choice, rate=rate_v, options=options_v, what=what, problems=problems)
    if problems:
        raise StudyError("; ".join(problems))
    assert n_runs is not None and dur is not None and seed_v is not None
    assert noise_v is not None
    study = Study(
        system=system, settings=fixed, axes=tuple(axes), sample=n_sample, runs=n_runs,
        duration=dur, x0={k: (v[0], v[1]) for k, v in x0_r.items()}, spread=spread_v,
        seed=seed_v, controller=chosen.text,
        noise=noise_v, delay=bool(delay), rate=rate_v, design_for=design_for, metrics=metrics,
        roa={k: (lo, hi, int(n)) for k, (lo, hi, n) in roa_r.items()}, batch_size=1,
        controller_options=options_v,
    )
    if study.n_points > MAX_POINTS:
        raise StudyError(f"the study has {study.n_points} points: at most {MAX_POINTS} per study "
                         "(split it, or draw a random sample)")
    if batch_size is None:
        batch_size = _default_batch_size(sysm, duration=dur, rates=_rates(rate_v, axes))
    size = _whole(batch_size, "batch_size", problems)
    if problems or size is None:
        raise StudyError("; ".join(problems))
    return replace(study, batch_size=min(size, n_runs))


def _study_system(system: str,
                  settings: Mapping[str, object] | None) -> tuple[dict[str, object], System]:
    """The study's fixed settings (numbers as floats: a study file's 1 and the command line's
    1.0 are one study) and its system with them; a system without input is refused."""
    from equilibrist.numeric.lookup import get_system
    from equilibrist.systems import files, registry

    # An unknown system or a bad system file is its own clear error.
    if files.looks_like_path(system):
        files.from_file(system)
    else:
        registry.lookup_family(system)
    fixed = {k: float(v) if isinstance(v, int | float) and not isinstance(v, bool) else v
             for k, v in (settings or {}).items()}
    sysm = get_system(system, **fixed)
    if sysm.n_inputs == 0:
        raise StudyError(f"{sysm.key} has no input: a study needs a controller to design")
    return fixed, sysm


def _axes(sysm: System, vary: Mapping[str, object] | Sequence[tuple[str, object]], *,
          sampled: bool, problems: list[str]) -> list[Axis]:
    """The varied quantities' axes; a quantity given twice is a problem. A parameter both
    varied and set (``--set m2=0.6 --vary m2=0.5:0.7:5``) runs at the varied values, and the
    set value is the nominal plant's (its design with ``--design-for nominal``)."""
    items = list(vary.items()) if isinstance(vary, Mapping) else list(vary)
    names = [n for n, _ in items]
    for n in sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"--vary {n} is given twice")
    axes = []
    for name, value in items:
        ax = _axis(sysm, str(name).strip(), value, sampled, problems)
        if ax is not None:
            axes.append(ax)
    if sampled and not items:
        problems.append("--sample random:N needs at least one --vary range")
    return axes


def _noise_scale(noise: float | str, problems: list[str]) -> float | None:
    """The noise's scale: a number >= 0, or ``on`` (1) and ``off`` (0)."""
    if isinstance(noise, str):
        noise_v = {"on": 1.0, "off": 0.0}.get(noise.strip().lower())
        if noise_v is None:
            noise_v = _number(noise, "--noise", problems)
    else:
        noise_v = _number(noise, "--noise", problems)
    if noise_v is not None and noise_v < 0:
        problems.append(f"--noise must be >= 0, got {noise_v:g}")
    return noise_v


def _spreads(sysm: System, spread: Mapping[str, object], problems: list[str]) -> dict[str, float]:
    """The relative spreads of the parameters, each in [0, 1)."""
    spec = sysm.spec
    spread_v: dict[str, float] = {}
    for name, rel in spread.items():
        if name not in spec.parameter_names:
            problems.append(f"--spread: unknown parameter {name!r} of {sysm.key} "
                            f"({nearest(name, spec.parameter_names)})")
            continue
        v = _number(rel, f"--spread {name}", problems)
        if v is not None and not 0 <= v < 1:
            problems.append(f"--spread {name}: expected a relative spread in [0, 1), got {v:g}")
        elif v is not None:
            spread_v[name] = v
    return spread_v


def _rates(rate: float, axes: Sequence[Axis]) -> list[float]:
    """The study's rate and every rate its axes reach [Hz]."""
    return [rate] + [float(v) for a in axes if a.kind == "rate"
                     for v in (a.values or (a.high,)) if v is not None]


def _check_run_samples(duration: float, rates: Sequence[float], problems: list[str]) -> None:
    """A run of *duration* at the fastest of *rates* has at most :data:`MAX_RUN_SAMPLES`
    samples."""
    fastest = max(rates)
    if duration * fastest > MAX_RUN_SAMPLES:
        problems.append(f"--duration {duration:g} s at {fastest:g} Hz is {duration * fastest:.3g} "
                        f"samples a run: at most {MAX_RUN_SAMPLES} ({MAX_RUN_SAMPLES / fastest:g} "
                        "s at that rate)")


def _default_batch_size(sysm: System, *, duration: float, rates: Sequence[float]) -> int:
    """Runs per compiled batch: as many as fit in :data:`BATCH_CELLS` cells of trajectories
    at the fastest of *rates* (8 to 1024)."""
    rows = int(duration * max(rates)) + 2
    width = 2 * sysm.n_states + len(sysm.output_names) + 3 * sysm.n_inputs
    return max(8, min(1024, BATCH_CELLS // (rows * width)))


def _controller_options(given: Mapping[str, object], kinds_used: Sequence[str],
                        problems: list[str]) -> dict[str, str]:
    """*given* checked against the options of the study's kinds, as text (files absolute)."""
    from equilibrist.controllers import kinds

    known = [k for k in dict.fromkeys(kinds_used) if k in controllers()]
    out: dict[str, str] = {}
    for key, value in given.items():
        options = [o for k in known for o in kinds.get(k).options if o.key == str(key)]
        if not options:
            takes = sorted({o.key for k in known for o in kinds.get(k).options})
            problems.append(f"controller_options {key}: no option of the study's controller(s) "
                            f"{', '.join(known) or '-'} (they take "
                            f"{', '.join(takes) or 'none'})")
            continue
        text = str(value).lower() if isinstance(value, bool) else str(value)
        try:
            for opt in options:
                opt.value(text)
        except kinds.KindError as exc:
            problems.append(f"controller_options {key}: {exc}")
            continue
        if any(is_file(o) for o in options):
            text = str(Path(text).expanduser().resolve())
            if not Path(text).is_file():
                problems.append(f"controller_options {key}: no file {text!r}")
                continue
        out[str(key)] = text
    return out


# -- study files ------------------------------------------------------------------------

_FILE_KEYS = ("system", "set", "vary", "sample", "runs", "duration", "x0", "spread", "seed",
              "controller", "noise", "delay", "rate", "design_for", "metrics", "roa",
              "batch_size", "controller_options")


def load_study_file(path: str | Path, *, system: str | None = None) -> Study:
    """A study from a TOML file (the keys of :func:`make_study`, ``system`` first; the
    format with examples in ``docs/studies.md``).

    A study file that names a Python system file never runs it: the user
    names that file as *system* (``equilibrist sweep FILE.py --study
    study.toml``), and its content must be the content of the file the study
    names where that one can still be read. *system* given with a study of a
    catalogue system must be that system.
    """
    import tomllib

    p = Path(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise StudyError(f"no study file {str(p)!r}") from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"study file {p}: not valid TOML ({exc})") from None
    unknown = sorted(set(data) - set(_FILE_KEYS))
    if unknown:
        raise StudyError(f"study file {p}: unknown key(s) {', '.join(unknown)} "
                         f"(expected {', '.join(_FILE_KEYS)})")
    if "system" not in data:
        raise StudyError(f"study file {p}: no system = \"...\"")
    for key in ("set", "vary", "x0", "spread", "roa", "controller_options"):
        if key in data and not isinstance(data[key], Mapping):
            raise StudyError(f"study file {p}: [{key}] must be a table of NAME = VALUE")
    sample = data.get("sample")
    if isinstance(sample, Mapping):
        if set(sample) != {"random"}:
            raise StudyError(f"study file {p}: [sample] takes random = N")
        sample = sample["random"]
    kwargs = {k: v for k, v in data.items() if k not in ("system", "sample")}
    if "controller_options" in data:
        kwargs["controller_options"] = _files_beside(p, data["controller_options"])
    if "controller" in data:
        kwargs["controller"] = _choice_beside(p, data["controller"])
    if isinstance(data.get("vary"), Mapping) and "controller" in data["vary"]:
        listed = data["vary"]["controller"]
        items = listed.split(",") if isinstance(listed, str) else listed
        kwargs["vary"] = {**data["vary"], "controller": [_choice_beside(p, v) for v in items]
                          if isinstance(items, list) else items}
    return make_study(_named_system(p, str(data["system"]), system), sample=sample, **kwargs)


def _files_beside(study_file: Path, options: Mapping[str, object]) -> dict[str, object]:
    """*options* with each relative file of a ``FILE...`` option read from the study file's folder."""
    from equilibrist.controllers import kinds

    files = {o.key for o in kinds.options() if is_file(o)}
    out = dict(options)
    for key, value in options.items():
        if key in files and isinstance(value, str) and not Path(value).expanduser().is_absolute():
            out[key] = str(study_file.parent / value)
    return out


def _choice_beside(study_file: Path, value: object) -> object:
    """A controller ``KIND:FILE`` of a study file with a relative file read from beside it."""
    from equilibrist.controllers import kinds

    if not isinstance(value, str):
        return value
    choice = parse_choice(value)
    if choice.value is None or choice.kind not in controllers():
        return value
    first = kinds.get(choice.kind).options[:1]
    if not (first and is_file(first[0])) or Path(choice.value).expanduser().is_absolute():
        return value
    return f"{choice.kind}:{study_file.parent / choice.value}"


def _named_system(study_file: Path, recorded: str, named: str | None) -> str:
    """The system a study file's *recorded* name stands for, given the user's *named* one."""
    from equilibrist.systems import files

    if not files.is_python_path(recorded):
        if named is not None and named != recorded:
            raise StudyError(f"study file {study_file} is a study of {recorded}, not of {named}")
        return recorded
    if named is None:
        raise StudyError(
            f"study file {study_file} names the Python system file {recorded}: a data file never "
            f"runs code; name the system yourself if you trust that file "
            f"(equilibrist sweep {recorded} --study {study_file})"
        )
    there = Path(recorded).expanduser()
    if not there.is_absolute():
        there = study_file.parent / there
    try:
        theirs = there.read_bytes() if there.is_file() else None
        mine = Path(named).expanduser().read_bytes()
    except OSError:
        return named  # a file that cannot be read is refused, in one line, by the study itself
    if theirs is not None and theirs != mine:
        raise StudyError(f"{named} is not the system file the study {study_file} names "
                         f"({recorded}): their contents differ")
    return named


__all__ = [
    "load_study_file",
    "make_study",
]
