"""The tour of one system: a controlled system (its realistic and ideal runs, plots,
animation, and the measures of the summary table) or the gyroscope (a steady and a
nutating precession)."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

import numpy as np

from equilibrist.apps.tour_common import (
    GYRO_DURATION,
    GYRO_SPIN,
    GYRO_THETA,
    SEED,
    Outcome,
    _fmt,
    _label,
    _slug,
    default_scenario,
)
from equilibrist.mechanics.spec import Scenario
from equilibrist.viz.report import Image, Section

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.numeric.system import System
    from equilibrist.sim.events import Pulse
    from equilibrist.sim.result import SimResult
    from equilibrist.sim.signals import Step

# -- one controlled system -----------------------------------------------------


class _RunOptions(TypedDict):
    """What the realistic and the ideal run of :func:`tour_controlled` share."""

    duration: float
    x0: np.ndarray
    reference: Step | None
    events: list[Pulse]


def tour_controlled(
    system: System,
    folder: Path,
    *,
    scenario: Scenario | None = None,
    size: tuple[int, int] = (400, 300),
    fps: float = 15.0,
    max_frames: int = 150,
    extras: bool = False,
    progress: bool = False,
    at: Mapping[str, float] | None = None,
) -> Outcome:
    """Design, simulate, plot and animate one system with an input into ``folder/<slug>``.

    *scenario* defaults to the rig's own (``SystemSpec.scenario``) or :func:`default_scenario`;
    *extras* adds a Monte-Carlo batch (the systems of :data:`ROA_SYSTEMS` get their region
    of attraction in any case); *at* names states of the operating point to design at.
    """
    from equilibrist.control import design
    from equilibrist.sim import StateFeedback

    began = time.perf_counter()
    d = design(system, rate=system.spec.control_rate, at=at)
    sc = scenario or system.spec.scenario or default_scenario(
        system, StateFeedback.from_design(d))
    slug = _slug(_label(system))
    sub = folder / slug
    sub.mkdir(parents=True, exist_ok=True)
    tracking = bool(sc.step) and d.Kc is not None
    push_at = sc.duration / 2
    main, ideal = _tour_runs(system, d, sc, tracking=tracking, push_at=push_at, progress=progress)
    main.save(sub / "run.npz")
    images = _tour_pictures(system, d, main, ideal, sub, slug, size=size, fps=fps,
                            max_frames=max_frames, progress=progress)
    notes: list[str] = [*([sc.note] if sc.note else []), *getattr(d, "notes", ())]
    if system.name in ("cartpole", "reaction_wheel_pendulum", "furuta", "acrobot"):
        from equilibrist.apps.swingup_demo import swingup_animation

        _gif, caption, energy = swingup_animation(system, sub, width=size[0], height=size[1],
                                                  fps=fps, max_frames=max_frames,
                                                  progress=progress)
        images.insert(1, Image(f"{slug}/swingup.gif", caption))
        from equilibrist.apps.planned_demo import planned_images

        images[2:2] = planned_images(system, sub, slug, notes, width=size[0], height=size[1],
                                     fps=fps, max_frames=max_frames, progress=progress,
                                     energy=energy)
        if system.name == "acrobot":
            from equilibrist.apps.robustness_demo import robustness_images

            images += robustness_images(system, sub, slug)
    roa_fact = None
    if system.key in ROA_SYSTEMS:
        roa_image, roa_fact = _roa(system, d, sub, slug)
        images.append(roa_image)
    if extras:
        images += _extras(system, d, sub, slug, sc, progress=progress)
        if system.name == "cartpole":
            from equilibrist.apps.mpc_demo import mpc_images

            images += mpc_images(system, sub, slug)
    row, story, facts = _tour_summary(system, d, sc, main, ideal, push_at=push_at,
                                      tracking=tracking, roa_fact=roa_fact, slug=slug)
    return Outcome(
        key=system.key,
        row=row,
        section=_section(system, slug, story, images, facts, notes),
        stayed_up=not main.fell,
        seconds=time.perf_counter() - began,
        simulated=sc.duration,
    )


def _tour_runs(system: System, d: Design, sc: Scenario, *, tracking: bool, push_at: float,
               progress: bool) -> tuple[SimResult, SimResult]:
    """The scenario's realistic run (the digital LQG, noisy sensors) and its ideal one (LQR
    on the true state, no noise): the same start, reference step and push."""
    from equilibrist.sim import LQG, Noise, Pulse, StateFeedback, Step, simulate

    x_op = np.asarray(d.plant.x0, float)
    x0 = x_op.copy()
    for name, offset in sc.start.items():
        x0[system.state_index(name)] += offset
    reference = None
    if tracking:
        r0 = np.asarray(d.r0, float)
        r1 = r0 + np.array([sc.step.get(n, 0.0) for n in d.tracked])
        reference = Step(value=r1, at=sc.step_at, initial=r0)
    events = [Pulse(time=push_at, value=sc.push, duration=sc.push_duration)] if sc.push else []
    common: _RunOptions = {"duration": sc.duration, "x0": x0, "reference": reference,
                           "events": events}
    lqg = LQG.from_design(d, tracking=tracking)
    main = simulate(system, lqg, noise=Noise.from_design(d), seed=SEED, progress=progress, **common)
    ideal = simulate(system, StateFeedback.from_design(d, tracking=tracking), **common)
    return main, ideal


def _tour_pictures(system: System, d: Design, main: SimResult, ideal: SimResult, sub: Path,
                   slug: str, *, size: tuple[int, int], fps: float, max_frames: int,
                   progress: bool) -> list[Image]:
    """The realistic run's response, its comparison with the ideal one, the poles and the
    animation, drawn into *sub*, with their captions."""
    from equilibrist.viz.animation import animate_result
    from equilibrist.viz.plots_maps import plot_poles
    from equilibrist.viz.plots_runs import plot_comparison, plot_response

    label_main = f"digital LQG at {d.rate:g} Hz, noisy sensors"
    plot_response(main, sub / "response.png",
                  title=f"{system.spec.title}: {label_main}, {'FELL' if main.fell else 'stayed up'}")
    plot_comparison({label_main: main, "ideal LQR on the true state, no noise": ideal},
                    sub / "comparison.png",
                    title=f"{system.spec.title}: what the estimator and the noise cost")
    plot_poles(d, sub / "poles.png")
    animate_result(main, sub / "animation.gif", width=size[0], height=size[1], fps=fps,
                   max_frames=max_frames, progress=progress)
    return [
        Image(f"{slug}/animation.gif", "The run, drawn to scale from the simulated states "
              "(time stamp top right; the gauge shows the input applied, red when saturated)."),
        Image(f"{slug}/poles.png", "Poles: open loop (x), with the LQR state feedback (o) and of "
              "the Kalman estimator (diamonds). The loop is stable when all closed-loop poles are "
              "inside the unit circle."),
        Image(f"{slug}/response.png", "Time response: true states (solid), the Kalman filter's "
              "estimates (dashed), the sensor readings (grey dots), the reference (dash-dot); the "
              "input applied, the command before saturation (dotted), the limits (red dashed).",
              wide=True),
        Image(f"{slug}/comparison.png", "The same run with the ideal loop: LQR on the true "
              "state without noise.", wide=True),
    ]


def _tour_summary(
    system: System, d: Design, sc: Scenario, main: SimResult, ideal: SimResult, *,
    push_at: float, tracking: bool, roa_fact: tuple[str, str] | None, slug: str,
) -> tuple[tuple[str, ...], list[str], list[tuple[str, str]]]:
    """The system's row of the summary table, its story and its facts, from the runs."""
    rate = f"{d.rate:g} Hz"
    m = main.metrics()
    u_name, u_unit = system.input_names[0], system.input_units[0]
    low, high = system.input_limits
    full = float(max(abs(low[0]), abs(high[0])))
    peak = float(np.abs(main.input(u_name)).max()) if main.n_rows else 0.0
    watched = watched_outputs(system, main)
    after = recovery_time(main, balance_outputs(system, main), push_at) if sc.push else None
    final = final_error(main, watched)
    errors = ", ".join(f"{w} {_fmt(v, main.unit(w), digits=2)}" for w, v in final.items())
    row = (
        _label(system),
        f"LQG {rate}",
        ("-" if main.fell or not sc.push else f"> {sc.duration - push_at:.0f} s")
        if after is None else f"{after:.2f} s",
        f"{peak:.3g} {u_unit} ({100 * peak / full:.0f} %)" if full > 0 else f"{peak:.3g} {u_unit}",
        errors,
        "no" if main.fell else "yes",
    )
    story = _story(system, d, sc, main, m, push_at=push_at, tracking=tracking, peak=peak, full=full,
                   after=after)
    facts = [
        ("controller", f"LQG: Kalman filter on {', '.join(d.output_names)} + LQR, {rate}"),
        ("start", ", ".join(f"{k} {_fmt(v, main.unit(k))} off the operating point"
                            for k, v in sc.start.items()) or "at the operating point"),
        ("reference step", ", ".join(f"{k} by {_fmt(v, main.unit(k))} at {sc.step_at:g} s"
                                     for k, v in sc.step.items()) if tracking else "none"),
        ("push", f"{sc.push_name} at {push_at:g} s" if sc.push else "none"),
        ("peak input", row[3]),
        ("time in saturation", f"{m['time_saturated']:.3g} s"),
        ("settling after the push", row[2]),
        ("final error (mean of the last second)", errors or "-"),
        ("estimation error (RMS)", ", ".join(
            f"{k} {_fmt(v, main.unit(k))}" for k, v in (m["estimation_error_rms"] or {}).items())),
        ("ideal loop (LQR, no noise)", "stayed up" if not ideal.fell else "fell"),
        *([roa_fact] if roa_fact else []),
        ("result file", f"{slug}/run.npz (equilibrist plot / equilibrist animate read it)"),
    ]
    return row, story, facts


#: The systems whose tour shows the LQR's region of attraction, estimated and certified.
ROA_SYSTEMS = ("cartpole", "furuta", "reaction_wheel_pendulum")


def _roa(system: System, d: Design, sub: Path, slug: str) -> tuple[Image, tuple[str, str]]:
    """The LQR's region of attraction as ``equilibrist roa`` finds it (its default slice, a
    smaller budget): the slice, the largest tilt and push, the certified level."""
    from equilibrist.control.linear import LinearController
    from equilibrist.sim.roa import default_bounds, default_slice
    from equilibrist.sim.roa_report import analyse
    from equilibrist.viz.plots_maps import plot_roa_slice

    ctrl = LinearController.from_design(d, kind="lqr")
    x_op, u_op = np.asarray(d.plant.x0, float), np.asarray(d.plant.u0, float)  # the design's point
    states = default_slice(system)
    assert states is not None  # the systems of ROA_SYSTEMS have a fall region
    assert d.rate is not None  # the tour designs at the rig's control rate
    bounds = default_bounds(system, states, x_op)
    report = analyse(system, ctrl, states=states, bounds=(bounds[states[0]], bounds[states[1]]),
                     x_op=x_op, u_op=u_op, samples=1500, boxes=ROA_BOXES, falsify=300,
                     seed=SEED, name="lqr",
                     options={"duration": 3.0, "rate": d.rate, "noise": None,
                              "physics_step": 1.0 / d.rate})
    f = report.figures
    plot_roa_slice(report, sub / "roa.png",
                   title=f"{system.spec.title}: the LQR's region of attraction "
                         f"({f['slice_samples']} runs)")
    cert = (f"certified level of dx' S dx: {f['rho']:.3g} (interval branch-and-bound on the "
            f"exact equations with saturation, continuous-time feedback; limited by "
            f"{f['certificate']['limited_by']}; {f['falsify_runs']} runs started inside it, "
            f"{f['counterexamples']} lost; it covers {f['coverage']:.0%} of the slice's caught "
            "area)") if f["certified"] else f"no certificate ({f['certificate_note']})"
    text = (f"tilt up to {f['max_tilt']:.3g} {f['tilt_unit']} and push up to "
            f"{f['max_push']:.3g} {f['push_unit']} recovered from rest; {cert}")
    caption = (f"Region of attraction of the LQR (no noise, 3 s per run): starts of the slice "
               f"{states[0]}, {states[1]}, refined along its boundary, caught (green) or not; "
               "the certified level of the LQR's V (solid) and the least V of a lost start "
               "(dashed). equilibrist roa computes it for any system.")
    return Image(f"{slug}/roa.png", caption), ("region of attraction (LQR)", text)


#: The certificate's box budget in the tour (equilibrist roa's default is 1,000,000).
ROA_BOXES = 250_000


def watched_outputs(system: System, result: SimResult) -> list[str]:
    """The outputs that say how well a run went: the tracked ones, then the
    states whose range defines falling (the balance), else the measured ones."""
    names = list(result.reference_names)
    names += [n for n in system.spec.region if n in system.state_names and n not in names]
    return names or list(result.output_names) or list(system.state_names)


def balance_outputs(system: System, result: SimResult) -> list[str]:
    """The states whose range decides a fall (the balance), else the watched outputs."""
    names = [n for n in system.spec.region if n in system.state_names]
    return names or watched_outputs(system, result)


def _errors(result: SimResult, names: Sequence[str]) -> np.ndarray:
    """Each watched output minus its target (its reference, else the operating point)."""
    cols = []
    for n in names:
        target = (result.reference_of(n) if n in result.reference_names
                  else np.full(result.n_rows, result.x_op[result.state_names.index(n)]))
        cols.append(result.state(n) - target)
    return np.column_stack(cols) if cols else np.zeros((result.n_rows, 0))


def recovery_time(result: SimResult, names: Sequence[str], push_at: float) -> float | None:
    """Seconds after *push_at* until the watched outputs are back for good.

    "Back" is within the larger of 1.5 times their excursion in the second
    before the push (the noise the loop lives with) and a tenth of the
    excursion the push caused. None when the run fell or never came back.
    """
    if result.fell or not names:
        return None
    t = result.time
    e = np.abs(_errors(result, names))
    before = (t >= push_at - 1.0) & (t < push_at)
    after = t >= push_at
    if not before.any() or not after.any():
        return None
    band = np.maximum(1.5 * e[before].max(axis=0), 0.1 * e[after].max(axis=0))
    outside = after & np.any(e > band, axis=1)
    if not outside.any():
        return 0.0
    last = int(np.nonzero(outside)[0][-1])
    if last >= len(t) - 1:
        return None
    return float(t[last + 1] - push_at)


def final_error(result: SimResult, names: Sequence[str], *,
                window: float = 1.0) -> dict[str, float]:
    """Mean of each watched output's error over the last *window* seconds."""
    if not result.n_rows:
        return {}
    e = _errors(result, names)
    tail = result.time >= result.time[-1] - window
    return {n: float(e[tail, j].mean()) for j, n in enumerate(names)}


def _story(system: System, d: Design, sc: Scenario, run: SimResult, m: Mapping[str, object], *,
           push_at: float,
           tracking: bool, peak: float, full: float, after: float | None) -> list[str]:
    unit = system.input_units[0]
    start = ", ".join(f"{k} = {_fmt(v, run.unit(k))}" for k, v in sc.start.items())
    first = (
        f"The run starts off balance ({start} from the operating point). A digital LQG "
        f"controller at {d.rate:g} Hz reads only the noisy sensors ({', '.join(d.output_names)}), "
        "estimates the full state with a Kalman filter and commands "
        f"{system.input_names[0]} within its limits."
    )
    if tracking:
        steps = ", ".join(f"{k} by {_fmt(v, run.unit(k))}" for k, v in sc.step.items())
        first += f" At {sc.step_at:g} s the reference asks it to move {steps}."
    if sc.push:
        first += f" At {push_at:g} s it gets {sc.push_name}."
    if run.fell:
        second = (f"It fell: {run.fell_state} left its safe range at {run.fell_at:.2f} s. "
                  "The scenario is harder than this controller can take.")
    else:
        second = "It stayed up"
        if sc.push:
            second += (f" and settled again {after:.2f} s after the push" if after is not None
                       else " but had not settled again by the end of the run")
        second += (f"; the input peaked at {peak:.3g} {unit}, {100 * peak / full:.0f} % of its "
                   f"limit, and was saturated for {m['time_saturated']:.2g} s.")
    return [system.spec.description, first, second]


def _section(system: System, slug: str, story: list[str], images: list[Image],
             facts: list[tuple[str, str]], notes: list[str]) -> Section:
    from equilibrist.mechanics.printing import equations_latex, equations_text

    model = system.symbolic
    return Section(
        anchor=slug,
        title=system.spec.title,
        subtitle=f"{_label(system)}: {system.spec.description}",
        story=story[1:],
        images=images,
        facts=facts,
        equations=equations_text(model, system.spec),
        equations_latex=equations_latex(model, system.spec),
        notes=notes,
    )


def _extras(system: System, d: Design, sub: Path, slug: str, sc: Scenario, *,
            progress: bool) -> list[Image]:
    """The Monte-Carlo fan (the cart-pole's tour)."""
    from equilibrist.sim import LQG, Noise, monte_carlo
    from equilibrist.viz.plots_runs import plot_fan

    lqg = LQG.from_design(d)
    spread = {n: 0.3 for n in ("m_p", "l", "m_c") if n in system.params}
    mc = monte_carlo(system, lqg, spread=spread, runs=40, seed=SEED, duration=sc.duration,
                     x0={k: float(d.plant.x0[system.state_index(k)]) + v for k, v in sc.start.items()},
                     noise=Noise.from_design(d), record=True, progress=progress)
    runs = [mc.batch.run(i) for i in range(mc.batch.runs)]
    spread_text = ", ".join(f"{k} ±{100 * v:.0f} %" for k, v in spread.items())
    if len(set(spread.values())) == 1:  # one spread for all: "m_p, l, m_c ±30 %"
        short = f"{', '.join(spread)} ±{100 * next(iter(spread.values())):.0f} %"
    else:
        short = spread_text
    plot_fan(runs, sub / "monte_carlo.png",
             title=f"{system.spec.title}: 40 runs with {short} (nominal controller), "
                   f"{mc.batch.stayed_up} stayed up")
    return [
        Image(f"{slug}/monte_carlo.png", "Monte-Carlo fan: the spread of 40 runs whose plant "
              f"parameters differ from the design's ({spread_text}): median, 25-75 % and "
              "5-95 % bands.", wide=True),
    ]


# -- the gyroscope -------------------------------------------------------------


def tour_gyroscope(
    system: System,
    folder: Path,
    *,
    size: tuple[int, int] = (400, 300),
    fps: float = 15.0,
    max_frames: int = 150,
    progress: bool = False,
) -> Outcome:
    """Steady and nutating precession of the heavy top (zxz variant)."""
    from equilibrist.sim import simulate
    from equilibrist.systems._gyro_tools import steady_precession_rates, zxz_to_xyz
    from equilibrist.viz.animation import animate_result
    from equilibrist.viz.plots_runs import plot_comparison, plot_response

    began = time.perf_counter()
    slug = _slug(_label(system))
    sub = folder / slug
    sub.mkdir(parents=True, exist_ok=True)
    euler = system.spec.variant[1] if system.spec.variant else "zxz"
    slow, fast = steady_precession_rates(system, GYRO_THETA, GYRO_SPIN)
    zxz = {
        "steady": np.array([0.0, GYRO_THETA, 0.0, slow, 0.0, GYRO_SPIN]),
        "nutating": np.array([0.0, GYRO_THETA, 0.0, 0.0, 0.0, GYRO_SPIN]),
    }
    starts = {k: (v if euler == "zxz" else zxz_to_xyz(v)) for k, v in zxz.items()}
    runs = {k: simulate(system, None, duration=GYRO_DURATION, rate=500.0, x0=x0,
                        integrator="adaptive", progress=progress)
            for k, x0 in starts.items()}
    for k, r in runs.items():
        r.save(sub / f"{k}.npz")
        animate_result(r, sub / f"{k}.gif", width=size[0], height=size[1], fps=fps,
                       max_frames=max_frames, speed=0.25, progress=progress)
    labels = {"steady": f"steady: released at the slow precession rate {slow:.3g} rad/s",
              "nutating": "nutating: released without precession"}
    axis_states = [n for n in ("theta", "phi_dot", "theta_dot") if n in system.state_names]
    plot_comparison({labels[k]: r for k, r in runs.items()}, sub / "comparison.png",
                    states=axis_states if euler == "zxz" else None, inputs=False,
                    title=f"{system.spec.title}: steady vs nutating precession")
    plot_response(runs["nutating"], sub / "response.png",
                  title=f"{system.spec.title}: nutating precession")
    theta_idx = system.state_index("theta")
    drift = {k: float(r.states[-1, theta_idx] - r.states[0, theta_idx]) for k, r in runs.items()}
    energy = {k: _relative_drift([system.energy(x) for x in (r.states[0], r.states[-1])])
              for k, r in runs.items()}
    fell = any(r.fell for r in runs.values())
    row = (_label(system), "none (no input)", "-", "-",
           f"theta drift {_fmt(drift['steady'], 'rad')} (steady)", "no" if fell else "yes")
    story = [
        f"The wheel spins at {GYRO_SPIN:g} rad/s with its axis tilted {math.degrees(GYRO_THETA):.0f}° "
        f"from vertical. For that tilt and spin the steady-precession relation has two roots: "
        f"a slow precession of {slow:.3g} rad/s and a fast one of {fast:.3g} rad/s.",
        f"Released at the slow rate, the axis sweeps round at constant tilt: its tilt drifted by "
        f"{_fmt(drift['steady'], 'rad')} in {GYRO_DURATION:g} s. Released without precession, it "
        "dips and nods (nutation) while it precesses: the blue trace of its tip draws the cusps. "
        f"Nothing drives or brakes it, so the energy is conserved: it drifted by "
        f"{energy['steady']:.1e} (steady) and {energy['nutating']:.1e} (nutating), relative.",
        "The animations play at a quarter of real speed so that the nutation shows.",
    ]
    images = [
        Image(f"{slug}/steady.gif", "Steady precession (slow motion x0.25): the axis keeps its tilt."),
        Image(f"{slug}/nutating.gif", "Nutating precession (slow motion x0.25): the tip traces cusps."),
        Image(f"{slug}/comparison.png", "Tilt and precession rate of both runs.", wide=True),
        Image(f"{slug}/response.png", "Every state of the nutating run.", wide=True),
    ]
    facts = [
        ("spin psi_dot", f"{GYRO_SPIN:g} rad/s"),
        ("tilt theta", f"{math.degrees(GYRO_THETA):.1f} deg"),
        ("steady precession rates (slow, fast)", f"{slow:.4g}, {fast:.4g} rad/s"),
        ("tilt drift, steady run", _fmt(drift["steady"], "rad")),
        ("tilt range, nutating run", _fmt(float(np.ptp(runs["nutating"].states[:, theta_idx])), "rad")),
        ("relative energy drift (steady, nutating)", f"{energy['steady']:.1e}, {energy['nutating']:.1e}"),
        ("result files", f"{slug}/steady.npz, {slug}/nutating.npz"),
    ]
    return Outcome(key=system.key, row=row,
                   section=_section(system, slug, [system.spec.description, *story], images, facts, []),
                   stayed_up=not fell, seconds=time.perf_counter() - began,
                   simulated=GYRO_DURATION)


def _relative_drift(values: Sequence[float]) -> float:
    a, b = float(values[0]), float(values[-1])
    return abs(b - a) / max(abs(a), 1e-300)
