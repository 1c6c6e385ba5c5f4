"""The linear controller form in C: one fixed piece of code in every export.

:data:`LINEAR_C` is the C99 transcription of the compiled linear controller
(:data:`equilibrist.control.controller.LINEAR_SOURCE`): the same sums in the
same order, so that in double precision, built without fused multiply-adds,
the exported controller and the simulated one agree to the last bit. It is
written into each exported source unchanged, after ``#define EQ_REAL``
names the library's number type; everything specific to a controller is in
the constants the generator writes around it (an ``eq_linear_form`` with
the sizes and the matrices, row-major).

It is tested on its own (``tests/test_export_linear_c.py``) against the
Python controller on random forms, in double and single precision.
"""

from __future__ import annotations

#: The fixed C code of the linear form (needs ``EQ_REAL`` and ``<stddef.h>``).
LINEAR_C = r"""/* ---- The linear controller form: the same code in every export. ----
 * u  = u_op + Cc z + Dy (y - y_op) + Dr (r - r_op)
 * z+ = Ac z + By (y - y_op) + Br (r - r_op) + Bu (u_applied - u_op)
 * x_hat - x_op = Ez z + Ey (y - y_op)
 * Matrices row-major; a block with no elements is NULL. r == NULL holds r at r_op. */
typedef struct {
    int nz, ny, nr, m, n;
    const EQ_REAL *Ac, *By, *Br, *Bu, *Cc, *Dy, *Dr, *Ez, *Ey;
    const EQ_REAL *u_op, *y_op, *r_op;
} eq_linear_form;

static EQ_REAL eq_reference(const eq_linear_form *f, const EQ_REAL *r, int j)
{
    return r != NULL ? r[j] : f->r_op[j];
}

static void eq_linear_output(const eq_linear_form *f, const EQ_REAL *z, const EQ_REAL *y,
                             const EQ_REAL *r, EQ_REAL *u)
{
    int i, j;
    for (i = 0; i < f->m; ++i) {
        EQ_REAL v = 0;
        for (j = 0; j < f->nz; ++j) {
            v += f->Cc[i * f->nz + j] * z[j];
        }
        for (j = 0; j < f->ny; ++j) {
            v += f->Dy[i * f->ny + j] * (y[j] - f->y_op[j]);
        }
        for (j = 0; j < f->nr; ++j) {
            v += f->Dr[i * f->nr + j] * (eq_reference(f, r, j) - f->r_op[j]);
        }
        u[i] = f->u_op[i] + v;
    }
}

static void eq_linear_update(const eq_linear_form *f, const EQ_REAL *z, const EQ_REAL *y,
                             const EQ_REAL *r, const EQ_REAL *u_applied, EQ_REAL *z_out)
{
    int i, j;
    for (i = 0; i < f->nz; ++i) {
        EQ_REAL v = 0;
        for (j = 0; j < f->nz; ++j) {
            v += f->Ac[i * f->nz + j] * z[j];
        }
        for (j = 0; j < f->ny; ++j) {
            v += f->By[i * f->ny + j] * (y[j] - f->y_op[j]);
        }
        for (j = 0; j < f->nr; ++j) {
            v += f->Br[i * f->nr + j] * (eq_reference(f, r, j) - f->r_op[j]);
        }
        for (j = 0; j < f->m; ++j) {
            v += f->Bu[i * f->m + j] * (u_applied[j] - f->u_op[j]);
        }
        z_out[i] = v;
    }
}

static void eq_linear_estimate(const eq_linear_form *f, const EQ_REAL *z, const EQ_REAL *y,
                               EQ_REAL *dx)
{
    int i, j;
    for (i = 0; i < f->n; ++i) {
        EQ_REAL v = 0;
        for (j = 0; j < f->nz; ++j) {
            v += f->Ez[i * f->nz + j] * z[j];
        }
        for (j = 0; j < f->ny; ++j) {
            v += f->Ey[i * f->ny + j] * (y[j] - f->y_op[j]);
        }
        dx[i] = v;
    }
}
/* ---- end of the linear controller form ---- */
"""

#: The blocks of ``eq_linear_form``, in the order of its initializer.
FORM_BLOCKS = ("Ac", "By", "Br", "Bu", "Cc", "Dy", "Dr", "Ez", "Ey", "u_op", "y_op", "r_op")
