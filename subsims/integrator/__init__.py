"""Integrators of the paper's §2.3, exact for polynomial input interpolants.

Used by the coupler's exact tests: stage n of y' = k y is the n-th Taylor polynomial (eq. 5).
"""
