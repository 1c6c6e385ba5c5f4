"""The linear controller form in C, as every export writes it: :data:`LINEAR_C` and
:data:`FORM_BLOCKS` of :mod:`equilibrist.control._linear_c` (in the control layer, where the
MPC's compiled runtime reads it too)."""

from equilibrist.control._linear_c import FORM_BLOCKS, LINEAR_C

__all__ = ["FORM_BLOCKS", "LINEAR_C"]
