"""The swing-up controller with its supervisor as a C99 library.

:func:`swingup_files` writes ``<name>.h`` and ``<name>.c``: the law of
:data:`equilibrist.control.swingup.LAW_SOURCE` line for line in C, its
constants (the controller's parameter vector) as one ``static const``
array, and the layout's slots as macros generated from the same layout.
The arithmetic is double precision, each expression in the same order as
the Python source, so compiled without contraction of multiply-adds
(``-ffp-contract=off``) it gives the Python controller's commands bit for
bit on the same inputs.

Math functions: ``cos``, ``sin`` and ``floor`` from the C library's
``<math.h>`` (link with ``-lm``). No dynamic memory; the controller's state
is ``<NAME>_NZ`` doubles (14: the tracker's estimate, the mode, the held
reference and the Kalman filter's state of the LQG hand-over).

The API::

    void <name>_init(<name>_state *s);
    void <name>_output(const <name>_state *s, const double y[2], double u[1]);
    void <name>_update(<name>_state *s, const double y[2], const double u_applied[1]);
    void <name>_estimate(const <name>_state *s, const double y[2], double x[4]);

``y`` are the measured coordinates (absolute, in the order of the
controller's outputs), ``u`` the command (already inside the actuator's
limits), ``u_applied`` the input that acted.
"""

from __future__ import annotations

import ctypes
import hashlib
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control.swingup import N_STATES, Z, layout_constants
from equilibrist.errors import ExportError
from equilibrist.export._check import ControllerExport, Described, Steps
from equilibrist.export.writer import register_exporter

if TYPE_CHECKING:
    from equilibrist.control.controller import NonlinearController
    from equilibrist.hil.firmware import Adapter
    from equilibrist.numeric.system import System

#: The C library functions the exported code calls.
MATH_FUNCTIONS = ("cos", "sin", "floor")

_BODY = r"""
#define SU_PI 3.141592653589793

static double su_wrap(double a)
{
    return a - 2.0 * SU_PI * floor((a + SU_PI) / (2.0 * SU_PI));
}

static double su_sign(double v)
{
    if (v > 0.0) return 1.0;
    if (v < 0.0) return -1.0;
    return 0.0;
}

static double su_clip(double v, double lo, double hi)
{
    if (v < lo) return lo;
    if (v > hi) return hi;
    return v;
}

static double su_energy(double x0, double x1, double x2, double x3, const double *p)
{
    int law = (int)p[SU_LAW];
    int ph = SU_PHYS;
    if (law == 3) {
        double m1 = p[ph], m2 = p[ph + 1], l1 = p[ph + 2], lc1 = p[ph + 3], lc2 = p[ph + 4];
        double i1 = p[ph + 5], i2 = p[ph + 6], g = p[ph + 7];
        double c2 = cos(x1);
        double d1 = m1 * lc1 * lc1 + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * c2) + i1 + i2;
        double d2 = m2 * (lc2 * lc2 + l1 * lc2 * c2) + i2;
        double d3 = m2 * lc2 * lc2 + i2;
        double kin = 0.5 * (d1 * x2 * x2 + 2.0 * d2 * x2 * x3 + d3 * x3 * x3);
        double pot = -g * (m1 * lc1 * cos(x0) + m2 * (l1 * cos(x0) + lc2 * cos(x0 + x1)));
        return kin + pot - g * (m1 * lc1 + m2 * (l1 + lc2));
    }
    return 0.5 * p[ph] * x3 * x3 + p[ph + 1] * (cos(x1) - 1.0);
}

static double su_pump(double x0, double x1, double x2, double x3, const double *p)
{
    int law = (int)p[SU_LAW];
    int ph = SU_PHYS;
    double e = su_energy(x0, x1, x2, x3, p) - p[SU_E0];
    double ke = p[SU_KE];
    double amax = p[SU_AMAX];
    if (law == 0) {
        double a = su_clip(ke * e * su_sign(x3 * cos(x1)), -amax, amax);
        double mlc, th_dd;
        a = a - p[SU_KX] * x0 - p[SU_KV] * x2;
        mlc = p[ph + 4] * cos(x1);
        th_dd = (p[ph + 1] * sin(x1) - p[ph + 5] * x3 - mlc * a) / p[ph];
        return (p[ph + 2] * a + mlc * th_dd - p[ph + 4] * sin(x1) * x3 * x3
                + p[ph + 3] * x2);
    }
    if (law == 1) {
        return su_clip(ke * e * su_sign(x3), -amax, amax) - p[SU_KV] * (x2 - x3);
    }
    if (law == 2) {
        return su_clip(ke * e * su_sign(x3 * cos(x1)), -amax, amax) - p[SU_KV] * x2;
    }
    {
        double m1 = p[ph], m2 = p[ph + 1], l1 = p[ph + 2], lc1 = p[ph + 3], lc2 = p[ph + 4];
        double i1 = p[ph + 5], i2 = p[ph + 6], g = p[ph + 7];
        double t2 = su_wrap(x1);
        double c2 = cos(t2);
        double s2 = sin(t2);
        double m11 = m1 * lc1 * lc1 + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * c2) + i1 + i2;
        double m12 = m2 * (lc2 * lc2 + l1 * lc2 * c2) + i2;
        double m22 = m2 * lc2 * lc2 + i2;
        double det = m11 * m22 - m12 * m12;
        double hg2 = m2 * l1 * lc2 * s2 * x2 * x2 + m2 * lc2 * g * sin(x0 + t2);
        double hg1 = (-m2 * l1 * lc2 * s2 * (2.0 * x2 * x3 + x3 * x3)
                      + (m1 * lc1 + m2 * l1) * g * sin(x0) + m2 * lc2 * g * sin(x0 + t2));
        /* Xin and Kaneda's energy law: V = ke (E - E0)^2 / 2 + kd x3^2 / 2 + kp t2^2 / 2
           falls as dV/dt = -kv x3^2 (while the motor is not saturated). */
        double kd = p[SU_KD];
        double num = -(p[SU_KV] * x3 + p[SU_KP] * t2) * det + kd * (m11 * hg2 - m12 * hg1);
        double den = ke * e * det + kd * m11;
        if (den == 0.0) return 0.0;
        return num / den;
    }
}

static double su_xhat(const double *z, const double *y, const double *p, int i)
{
    if (z[SU_Z_INIT] == 0.0) {
        if (i < 2) return y[i];
        return 0.0;
    }
    if (i < 2) return z[SU_Z_XHAT + i] + p[SU_ALPHA] * (y[i] - z[SU_Z_XHAT + i]);
    return z[SU_Z_XHAT + i] + p[SU_BETA] / p[SU_T] * (y[i - 2] - z[SU_Z_XHAT + i - 2]);
}

static double su_ref(const double *z, double xi, const double *p, int i, int balancing)
{
    if (balancing) return z[SU_Z_REF + i];
    if (p[SU_FREE + i] != 0.0) return xi;
    return p[SU_X_OP + i];
}

static double su_dev(double xi, double ri, const double *p, int i)
{
    double d = xi - ri;
    if (p[SU_WRAP + i] != 0.0) d = su_wrap(d);
    return d;
}

static double su_level(double d0, double d1, double d2, double d3, const double *p)
{
    int s = SU_S;
    double v = 0.0;
    v += d0 * (p[s] * d0 + p[s + 1] * d1 + p[s + 2] * d2 + p[s + 3] * d3);
    v += d1 * (p[s + 4] * d0 + p[s + 5] * d1 + p[s + 6] * d2 + p[s + 7] * d3);
    v += d2 * (p[s + 8] * d0 + p[s + 9] * d1 + p[s + 10] * d2 + p[s + 11] * d3);
    v += d3 * (p[s + 12] * d0 + p[s + 13] * d1 + p[s + 14] * d2 + p[s + 15] * d3);
    return v;
}

/* The Kalman filter's estimate (deviation from the held reference) of state i while
   the LQG balances: current form kz + M (dy - C kz), predictor form kz. */
static double su_kest(const double *z, const double *y, const double *p, int i)
{
    int kz = SU_Z_KZ;
    int m = SU_KF + 2 * i;
    double e0, e1;
    if (p[SU_KFORM] != 0.0) return z[kz + i];
    e0 = su_dev(y[0], z[SU_Z_REF], p, 0) - z[kz];
    e1 = su_dev(y[1], z[SU_Z_REF + 1], p, 1) - z[kz + 1];
    return z[kz + i] + p[m] * e0 + p[m + 1] * e1;
}

/* The filter's prediction of state i for the next sample from this sample's estimate d
   (at the hand-over: the tracker's), the predictor form's correction once it runs. */
static double su_kpred(const double *z, const double *y, const double *p, int i, double d0,
                       double d1, double d2, double d3, double du, int balancing)
{
    int a = SU_AD + 4 * i;
    double v = p[a] * d0 + p[a + 1] * d1 + p[a + 2] * d2 + p[a + 3] * d3 + p[SU_BD + i] * du;
    if (balancing && p[SU_KFORM] != 0.0) {
        int kz = SU_Z_KZ;
        int m = SU_KF + 2 * i;
        double e0 = su_dev(y[0], z[SU_Z_REF], p, 0) - z[kz];
        double e1 = su_dev(y[1], z[SU_Z_REF + 1], p, 1) - z[kz + 1];
        v = v + p[m] * e0 + p[m + 1] * e1;
    }
    return v;
}

static double su_mode(const double *z, double v, const double *p)
{
    if (z[SU_Z_MODE] == 1.0) {
        if (v <= p[SU_C_OUT]) return 1.0;
        return 0.0;
    }
    if (v < p[SU_C_IN]) return 1.0;
    return 0.0;
}

void NAME_init(NAME_state *s)
{
    int i;
    for (i = 0; i < NAME_NZ; ++i) s->z[i] = 0.0;
}

void NAME_output(const NAME_state *s, const double y[2], double u[1])
{
    const double *z = s->z;
    const double *p = NAME_params;
    double x0 = su_xhat(z, y, p, 0);
    double x1 = su_xhat(z, y, p, 1);
    double x2 = su_xhat(z, y, p, 2);
    double x3 = su_xhat(z, y, p, 3);
    int bal = z[SU_Z_MODE] == 1.0;
    double d0 = su_dev(x0, su_ref(z, x0, p, 0, bal), p, 0);
    double d1 = su_dev(x1, su_ref(z, x1, p, 1, bal), p, 1);
    double d2 = su_dev(x2, su_ref(z, x2, p, 2, bal), p, 2);
    double d3 = su_dev(x3, su_ref(z, x3, p, 3, bal), p, 3);
    double mode = su_mode(z, su_level(d0, d1, d2, d3, p), p);
    double raw;
    if (mode == 1.0 && bal && p[SU_LQG] != 0.0) {
        d0 = su_kest(z, y, p, 0);
        d1 = su_kest(z, y, p, 1);
        d2 = su_kest(z, y, p, 2);
        d3 = su_kest(z, y, p, 3);
    }
    if (mode == 1.0) {
        int k = SU_K;
        raw = p[SU_U_OP] - (p[k] * d0 + p[k + 1] * d1 + p[k + 2] * d2 + p[k + 3] * d3);
    } else {
        raw = su_pump(x0, x1, x2, x3, p);
    }
    u[0] = su_clip(raw, p[SU_U_MIN], p[SU_U_MAX]);
}

void NAME_update(NAME_state *s, const double y[2], const double u_applied[1])
{
    const double *p = NAME_params;
    double z[NAME_NZ];
    double x0, x1, x2, x3, r0, r1, r2, r3, d0, d1, d2, d3, du, mode;
    int i, bal, lqg;
    for (i = 0; i < NAME_NZ; ++i) z[i] = s->z[i];
    x0 = su_xhat(z, y, p, 0);
    x1 = su_xhat(z, y, p, 1);
    x2 = su_xhat(z, y, p, 2);
    x3 = su_xhat(z, y, p, 3);
    bal = z[SU_Z_MODE] == 1.0;
    r0 = su_ref(z, x0, p, 0, bal);
    r1 = su_ref(z, x1, p, 1, bal);
    r2 = su_ref(z, x2, p, 2, bal);
    r3 = su_ref(z, x3, p, 3, bal);
    d0 = su_dev(x0, r0, p, 0);
    d1 = su_dev(x1, r1, p, 1);
    d2 = su_dev(x2, r2, p, 2);
    d3 = su_dev(x3, r3, p, 3);
    lqg = p[SU_LQG] != 0.0;
    mode = su_mode(z, su_level(d0, d1, d2, d3, p), p);
    if (mode == 1.0 && bal && lqg) {
        d0 = su_kest(z, y, p, 0);
        d1 = su_kest(z, y, p, 1);
        d2 = su_kest(z, y, p, 2);
        d3 = su_kest(z, y, p, 3);
    }
    du = u_applied[0] - p[SU_U_OP];
    for (i = 0; i < 4; ++i) {
        if (lqg && mode == 1.0) {
            s->z[SU_Z_KZ + i] = su_kpred(z, y, p, i, d0, d1, d2, d3, du, bal);
        } else {
            s->z[SU_Z_KZ + i] = 0.0;
        }
    }
    s->z[SU_Z_INIT] = 1.0;
    s->z[SU_Z_MODE] = mode;
    s->z[SU_Z_REF] = r0;
    s->z[SU_Z_REF + 1] = r1;
    s->z[SU_Z_REF + 2] = r2;
    s->z[SU_Z_REF + 3] = r3;
    s->z[SU_Z_XHAT] = x0 + p[SU_T] * x2;
    s->z[SU_Z_XHAT + 1] = x1 + p[SU_T] * x3;
    s->z[SU_Z_XHAT + 2] = x2;
    s->z[SU_Z_XHAT + 3] = x3;
}

void NAME_estimate(const NAME_state *s, const double y[2], double x[4])
{
    const double *p = NAME_params;
    int i;
    if (s->z[SU_Z_MODE] == 1.0 && p[SU_LQG] != 0.0) {
        for (i = 0; i < 4; ++i) x[i] = s->z[SU_Z_REF + i] + su_kest(s->z, y, p, i);
        return;
    }
    x[0] = su_xhat(s->z, y, p, 0);
    x[1] = su_xhat(s->z, y, p, 1);
    x[2] = su_xhat(s->z, y, p, 2);
    x[3] = su_xhat(s->z, y, p, 3);
}
"""


def swingup_files(ctrl: NonlinearController, *, name: str = "swingup") -> dict[str, str]:
    """``{"<name>.h": ..., "<name>.c": ...}`` of the swing-up controller *ctrl*."""
    if ctrl.name != "swingup":
        raise ExportError(f"expected a swing-up controller, got {ctrl.name!r}")
    if not name.isidentifier():
        raise ExportError(f"the library's name must be a C identifier, got {name!r}")
    guard = name.upper() + "_H"
    settings = ctrl.settings
    header = "\n".join([
        f"/* {name}: swing-up with supervisor ({settings.get('law', '')} law, balanced by the "
        f"{str(settings.get('balance', 'lqr')).upper()}), generated by equilibrist.",
        f" * Sample rate {ctrl.rate:g} Hz. Measured: {', '.join(ctrl.output_names)}.",
        f" * Input: {', '.join(ctrl.input_names)}. Needs cos, sin, floor from <math.h> (-lm). */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        f"#define {name.upper()}_NZ {Z['end']}",
        f"#define {name.upper()}_NY 2",
        f"#define {name.upper()}_NX {N_STATES}",
        f"#define {name.upper()}_RATE_HZ {ctrl.rate!r}",
        "",
        f"typedef struct {{ double z[{Z['end']}]; }} {name}_state;",
        "",
        f"void {name}_init({name}_state *s);",
        f"void {name}_output(const {name}_state *s, const double y[2], double u[1]);",
        f"void {name}_update({name}_state *s, const double y[2], const double u_applied[1]);",
        f"void {name}_estimate(const {name}_state *s, const double y[2], double x[4]);",
        "",
        f"#endif /* {guard} */",
        "",
    ])
    consts = "\n".join(f"#define {k} {v}" for k, v in layout_constants().items())
    params = ",\n    ".join(repr(float(v)) for v in ctrl.params)
    body = _BODY.replace("NAME_NZ", f"{name.upper()}_NZ").replace("NAME", name)
    source = (
        f'/* {name}.c: generated by equilibrist; the law of equilibrist.control.swingup. */\n'
        f'#include <math.h>\n#include "{name}.h"\n\n{consts}\n\n'
        f"static const double {name}_params[{ctrl.params.size}] = {{\n    {params}\n}};\n{body}"
    )
    return {f"{name}.h": header, f"{name}.c": source}


def recorded_vectors(ctrl: NonlinearController, system: System, *, duration: float = 4.0,
                     seed: int = 0) -> dict[str, np.ndarray]:
    """Test vectors: a swing-up of *system* under the plain-Python controller, with sensor noise.

    ``y`` (measurements), ``u_applied`` and ``u`` (the Python controller's
    commands), one row per sample.
    """
    from equilibrist.control.design import design as make_design
    from equilibrist.control.swingup import SwingUpRuntime
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.run import simulate
    from equilibrist.tasks import get_task

    task = get_task(system, "swingup")
    noise = Noise.from_design(make_design(system, rate=ctrl.rate))
    res = simulate(system, SwingUpRuntime(ctrl, compiled=False), duration=duration,
                   x0=task.draw_initial(np.random.default_rng(seed)), region={}, noise=noise,
                   seed=seed)
    return {"y": np.array(res.measurements), "u_applied": np.array(res.applied),
            "u": np.array(res.commanded)}


def check_files(name: str, vectors: dict[str, np.ndarray]) -> dict[str, str]:
    """``<name>_vectors.h``, ``test_<name>.c`` and a ``Makefile`` whose ``make check`` runs them.

    The test program feeds the recorded measurements and applied inputs to
    the library and requires every command to equal the recorded one
    exactly (double precision, no contraction of multiply-adds).
    """
    from equilibrist.export._check import check_files as shared

    k = len(vectors["y"])
    program = f"""    {name}_state s;
    int k, bad = 0;
    {name}_init(&s);
    for (k = 0; k < N_VECTORS; ++k) {{
        double u[1];
        {name}_output(&s, vec_y[k], u);
        if (u[0] != vec_u[k][0]) {{
            if (bad < 5) printf("sample %d: %.17g, expected %.17g\\n", k, u[0], vec_u[k][0]);
            ++bad;
        }}
        {name}_update(&s, vec_y[k], vec_u_applied[k]);
    }}
    printf("%d samples, %d mismatches\\n", N_VECTORS, bad);
    return bad != 0;"""
    return shared(
        name, {"y": vectors["y"], "u_applied": vectors["u_applied"], "u": vectors["u"]},
        comment=f"Recorded by equilibrist: {k} samples of a swing-up under the Python controller.",
        program=program, what="the library against the recorded Python commands, exactly.",
        cflags="-std=c99 -Wall -Wextra -Werror -pedantic -O2 -ffp-contract=off",
    )


def export_swingup(ctrl: NonlinearController, system: System, folder: str | Path, *,
                   name: str = "swingup", seed: int = 0) -> Path:
    """Write the swing-up library, its recorded test vectors and ``make check`` into *folder*."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    files = {**swingup_files(ctrl, name=name),
             **check_files(name, recorded_vectors(ctrl, system, seed=seed))}
    for fname, text in files.items():
        (out / fname).write_text(text)
    return out


#: What :func:`export_files` returns (kept under its former name).
SwingUpExport = ControllerExport


@register_exporter("swingup")
def export_files(ctrl: NonlinearController, out: str | Path, *, system: System,
                 precision: str = "double", duration: float | None = None, seed: int = 0,
                 force: bool = False) -> SwingUpExport:
    """``equilibrist export SYSTEM --controller swingup``: the library, vectors, ``make check``."""
    from equilibrist.export.writer import check_folder, write_files

    if precision != "double":
        raise ExportError(
            f"the swing-up is exported in double precision only (its test is bit for bit "
            f"against the Python controller), not {precision!r}"
        )
    from equilibrist.export.vectors import check_duration

    check_duration(duration, ctrl.rate)
    folder = check_folder(out, force=force)
    name = "swingup"
    vec = recorded_vectors(ctrl, system, duration=duration or 4.0, seed=seed)
    from equilibrist.hil.firmware import WHAT, with_hil

    files = with_hil({**swingup_files(ctrl, name=name), **check_files(name, vec)},
                     hil_adapter(ctrl, system, name=name),
                     sketch_copies=(f"{name}.h", f"{name}.c"))
    write_files(folder, files)
    what = {
        f"{name}.h": "the library's interface", f"{name}.c": "the swing-up and its supervisor",
        f"{name}_vectors.h": "recorded test vectors", f"test_{name}.c": "test program",
        "Makefile": "make check, make hil-host", **WHAT,
    }
    return SwingUpExport(folder=folder, name=name, files=what, precision="double",
                         data=Described(design_id(ctrl), "swingup", ctrl.rate),
                         vectors=Steps(len(vec["y"])))


def hil_adapter(ctrl: NonlinearController, system: System, *, name: str = "swingup") -> Adapter:
    """The swing-up behind the hardware-in-the-loop interface."""
    from equilibrist.hil.firmware import Adapter

    names = system.input_names
    step = f"""    {name}_estimate(&hil_s, y, est);
    {name}_output(&hil_s, y, u);
    hil_saturate(u, applied);
    {name}_update(&hil_s, y, applied);"""
    return Adapter(
        controller_id=design_id(ctrl), n=N_STATES, m=len(names), p=len(ctrl.output_names),
        references=0, estimate=N_STATES, rate=float(ctrl.rate),
        u_min=tuple(float(system.params[f"{i}_min"]) for i in names),
        u_max=tuple(float(system.params[f"{i}_max"]) for i in names),
        includes=(f"{name}.h",), sources=(f"{name}.c",), globals=f"static {name}_state hil_s;",
        init=f"    {name}_init(&hil_s);", step=step,
    )


def design_id(ctrl: NonlinearController) -> str:
    """12 hex digits naming the exported swing-up: its law's source and its numbers."""
    return hashlib.sha256(ctrl.params.tobytes() + ctrl.source.encode()).hexdigest()[:12]


class CompiledSwingUp:
    """The exported C swing-up compiled into a shared library and called through ctypes.

    A :class:`~equilibrist.control.controller.PythonController`
    (``reset``, ``output``, ``update``), so it closes the loop in the
    simulation: the code that runs on the robot.
    """

    def __init__(self, ctrl: NonlinearController, *, name: str = "swingup") -> None:
        from equilibrist.export.native import build_shared_library

        self.ctrl = ctrl
        self.rate: float | None = ctrl.rate
        self.outputs: tuple[str, ...] | None = ctrl.output_names
        self.estimate: np.ndarray | None = None
        self._dir = tempfile.TemporaryDirectory(prefix="equilibrist-swingup-")
        folder = Path(self._dir.name)
        for fname, text in swingup_files(ctrl, name=name).items():
            (folder / fname).write_text(text)
        lib = build_shared_library([folder / f"{name}.c"], folder / f"lib{name}.so",
                                   include=folder, extra_flags=("-lm",))
        self._lib: Any = ctypes.CDLL(str(lib))
        dp = ctypes.POINTER(ctypes.c_double)
        def function(fn: str, count: int) -> Any:
            f = getattr(self._lib, f"{name}_{fn}")
            f.argtypes = [dp] * count
            f.restype = None
            return f

        self._init = function("init", 1)
        self._output = function("output", 3)
        self._update = function("update", 3)
        self._estimate = function("estimate", 3)
        self._z = np.zeros(Z["end"])
        self.reset()

    @staticmethod
    def _ptr(a: np.ndarray) -> Any:
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def reset(self) -> None:
        self._init(self._ptr(self._z))
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        yv = np.ascontiguousarray(y, dtype=np.float64)
        u = np.zeros(1)
        x = np.zeros(N_STATES)
        self._estimate(self._ptr(self._z), self._ptr(yv), self._ptr(x))
        self._output(self._ptr(self._z), self._ptr(yv), self._ptr(u))
        self.estimate = x
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        yv = np.ascontiguousarray(y, dtype=np.float64)
        ua = np.ascontiguousarray(u_applied, dtype=np.float64)
        self._update(self._ptr(self._z), self._ptr(yv), self._ptr(ua))

    def close(self) -> None:
        self._dir.cleanup()


__all__ = ["MATH_FUNCTIONS", "CompiledSwingUp", "SwingUpExport", "check_files", "export_files", "export_swingup", "recorded_vectors", "swingup_files"]
