"""Any FMU as a subsim (FMI 2.0 / 3.0 via FMPy): ``python -m subsims.fmu model.fmu --connect EP --run RUN``.

In a scenario: ``[subsims.<name>]`` with ``fmu = "model.fmu"`` (a path relative to the scenario file),
or ``model = "subsims.fmu:FmuSubsim"`` with ``params.fmu``. See docs/fmi.md.
"""

from subsims.fmu.subsim import FmuSubsim

__all__ = ["FmuSubsim"]
