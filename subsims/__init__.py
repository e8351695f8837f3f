"""Shipped subsystem simulations. Each package is a process: ``python -m subsims.<name> --help``.

Physics modules (everything but the adapters ``*/subsim.py``, ``*/__main__.py``, ``*/plots.py`` and
``subsims.adapters``) import NumPy/SciPy, ``subsims.numerics`` (the one RK4, 3-vectors, the 3-2-1 DCM) and other
physics modules only, never ``cosim``.
"""
