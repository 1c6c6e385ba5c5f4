"""Numeric layer: symbolic model + parameter values -> fast functions, equilibria, linearization."""
