"""Aerodynamics subsim: six-facet box, constant density, drag and centre-of-pressure torque (paper §4.3)."""
