"""cosim: recursive-feedback co-simulation of stand-alone subsim processes over Eclipse Zenoh."""

from cosim.purity import ImpureModel, check_pure
from cosim.signals import Segment
from cosim.subsim import ModelError, Param, Port, Subsim

__all__ = ["ImpureModel", "ModelError", "Param", "Port", "Segment", "Subsim", "check_pure"]
__version__ = "0.1.0"
