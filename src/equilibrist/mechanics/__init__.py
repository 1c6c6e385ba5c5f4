"""Symbolic layer: system specifications and derivation with sympy.physics.mechanics."""
