"""Recursive-feedback coupling algorithms (sans-IO: they use only cosim.handles.SubsimHandle)."""
