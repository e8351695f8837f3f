"""Shipped subsystem simulations. Each package is a process: ``python -m subsims.<name> --help``."""
