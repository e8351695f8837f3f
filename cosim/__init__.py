"""cosim: recursive-feedback co-simulation of stand-alone subsim processes over Eclipse Zenoh."""

from typing import Any

from cosim.purity import ImpureModel, check_pure
from cosim.signals import Segment
from cosim.subsim import ModelError, Param, Port, Subsim

__all__ = ["ImpureModel", "ModelError", "Param", "Port", "Segment", "Subsim", "check_pure"]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    """``cosim.run`` (:func:`cosim.api.run`), imported on first use: a subsim process never loads the
    coordinator's side."""
    if name == "run":
        from cosim.api import run

        return run
    raise AttributeError(f"module 'cosim' has no attribute {name!r}")
