"""One region-of-attraction analysis, as ``equilibrist roa``, the demo and the playground run it.

:func:`analyse` estimates the slice, the largest tilt and push, certifies a
level of the LQR's ``V`` where the controller has one
(:func:`equilibrist.control.certify.certify`), starts runs inside that level
and checks it against every run that started inside: the figures of the
command's JSON (docs/roa.md), and what :func:`equilibrist.viz.plots_maps.plot_roa_slice`
draws.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.numeric.system import System
from equilibrist.sim.roa import (
    SliceEstimate,
    estimate_slice,
    levels_of,
    max_push,
    max_tilt,
    outcomes,
    rho_sampled,
    sample_level,
    slice_coverage,
)

if TYPE_CHECKING:
    from equilibrist.control.certify import Certificate
    from equilibrist.control.design_record import Design


@dataclass(frozen=True, eq=False)
class RoaReport:
    """The slice, every run started (``x0s``, ``caught``), the Riccati matrix ``S`` (None
    without one), the certificate (None without one) and the figures (docs/roa.md)."""

    system: System
    est: SliceEstimate
    x0s: np.ndarray
    caught: np.ndarray
    x_op: np.ndarray
    S: np.ndarray | None
    cert: Certificate | None
    figures: dict[str, Any]

    @property
    def rho_certified(self) -> float | None:
        """The certified level, when the runs inside it did not falsify it."""
        return float(self.figures["rho"]) if self.figures["certified"] else None


def analyse(system: System, controller: object, *, states: tuple[str, str],
            bounds: tuple[tuple[float, float], tuple[float, float]], x_op: np.ndarray,
            u_op: np.ndarray, samples: int, boxes: int | None, falsify: int, seed: int,
            options: Mapping[str, Any], name: str) -> RoaReport:
    """The analysis of ``equilibrist roa`` (*boxes* None: no certificate)."""
    opts = dict(options)
    est = estimate_slice(system, controller, states, bounds, x_op=x_op, max_samples=samples,
                         seed=seed, **opts)
    tilt_state = states[0]
    k = system.state_index(tilt_state)
    limit = max(abs(bounds[0][0] - x_op[k]), abs(bounds[0][1] - x_op[k]))
    down, up, tilt_x0, tilt_ok = max_tilt(system, controller, tilt_state, limit, x_op=x_op,
                                          seed=seed, **opts)
    lo_u, hi_u = system.input_limits
    push_limit = float(max(abs(lo_u[0]), abs(hi_u[0]))) if math.isfinite(float(hi_u[0])) else 100.0
    neg, pos, push_x0, push_ok = max_push(system, controller, push_limit, x_op=x_op, u_op=u_op,
                                          seed=seed, **opts)
    x0s = np.vstack([est.x0s, np.array(tilt_x0), np.array(push_x0)])
    caught = np.concatenate([est.caught, np.array(tilt_ok, dtype=bool),
                             np.array(push_ok, dtype=bool)])
    design = getattr(controller, "design", None)
    # A design for a delayed loop has its Riccati function on the plant's state and the
    # commands in flight, not on the plant's state alone that the starts are.
    delayed = bool(getattr(design, "delay", 0))
    S = None if delayed else getattr(design, "S", None)
    cert, note = None, None
    if design is not None and S is not None and boxes is not None:
        cert, note, extra = _certify(system, design, x_op, u_op, boxes, falsify, controller,
                                     opts, seed)
        if extra is not None:
            x0s = np.vstack([x0s, extra[0]])
            caught = np.concatenate([caught, extra[1]])
    elif boxes is not None and delayed:
        note = (f"--controller {name} designed for a delay has its Riccati function on the "
                "commands in flight too, not on the plant's state alone: nothing to certify")
    elif boxes is not None:
        note = f"--controller {name} has no Riccati function to certify (lqr and lqg have)"
    rho_est = None
    if S is not None:
        S = np.asarray(S, dtype=float)
        rho_est = rho_sampled(S, x_op, x0s, caught)  # the least V of a start that was lost
    figures = {
        "system": system.key, "controller": name, "slice": list(states),
        "bounds": {states[0]: list(bounds[0]), states[1]: list(bounds[1])},
        "samples": int(caught.size), "slice_samples": est.samples, "levels": est.levels,
        "fraction_caught": est.fraction_caught,
        "max_tilt": float(min(down, up)), "max_tilt_down": float(down), "max_tilt_up": float(up),
        "tilt_state": tilt_state, "tilt_unit": system.state_units[k],
        "max_push": float(min(neg, pos)), "max_push_negative": float(neg),
        "max_push_positive": float(pos), "push_unit": f"{system.input_units[0]} s",
        "rho_sampled": (None if rho_est is None or math.isinf(rho_est) else rho_est),
        **_checked(cert, note, system, S, x_op, x0s, caught, est, states),
    }
    return RoaReport(system=system, est=est, x0s=x0s, caught=caught, x_op=x_op, S=S, cert=cert,
                     figures=figures)


def _certify(system: System, design: Design, x_op: np.ndarray, u_op: np.ndarray, boxes: int,
             falsify: int, controller: object, options: dict[str, object], seed: int
             ) -> tuple[Certificate | None, str | None, tuple[np.ndarray, np.ndarray] | None]:
    """The certificate and the runs started inside it (or why there is none)."""
    from equilibrist.control.certify import boxes_bar, certify
    from equilibrist.control.lyapunov_rate import CertificateUnavailable

    try:
        with boxes_bar(boxes, bool(options.get("progress"))) as counted:
            cert = certify(system, design.K, design.S, x_op=x_op, u_op=u_op, max_boxes=boxes,
                           counted=counted)
    except CertificateUnavailable as err:
        return None, str(err), None
    if falsify == 0:
        return cert, None, None
    starts = sample_level(design.S, x_op, cert.rho, falsify, seed=seed + 77)
    return cert, None, (starts, outcomes(system, controller, starts, options, seed + 77))


def _checked(cert: Certificate | None, note: str | None, system: System, S: np.ndarray | None,
             x_op: np.ndarray, x0s: np.ndarray, caught: np.ndarray, est: SliceEstimate,
             states: tuple[str, str]) -> dict[str, object]:
    """The certificate's JSON keys, checked against every run that started inside it."""
    if cert is None or S is None:  # S is None only without a certificate
        return {"rho": None, "certified": False, "method": None, "counterexamples": None,
                "coverage": None, "falsify_runs": 0, "certificate": None,
                "certificate_note": note}
    inside = levels_of(S, x_op, x0s) <= cert.rho
    fell = int((inside & ~caught).sum())
    idx = (system.state_index(states[0]), system.state_index(states[1]))
    return {
        "rho": cert.rho, "certified": fell == 0, "method": cert.method,
        "counterexamples": fell, "coverage": slice_coverage(est, S, x_op, idx, cert.rho),
        "falsify_runs": int(inside.sum()), "certificate": cert.to_dict(),
        "certificate_note": None if fell == 0 else (
            f"{fell} runs started inside the proven level fell: the sampled loop differs from "
            "the continuous one the proof assumes"),
    }


__all__ = ["RoaReport", "analyse"]
