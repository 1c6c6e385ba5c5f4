"""The linear controller's library in C, as every export writes it: :func:`linear_c` and
:func:`deviation_vector` of :mod:`equilibrist.control._linear_c` (in the control layer, where
the MPC's compiled runtime reads it too)."""

from equilibrist.control._linear_c import deviation_vector, linear_c

__all__ = ["deviation_vector", "linear_c"]
