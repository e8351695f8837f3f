"""Orbit dynamics subsim: point mass, inverse-square gravity, aerodynamic force input (paper §4.1)."""
