"""cosim: recursive-feedback co-simulation of stand-alone subsim processes over Eclipse Zenoh."""

from cosim.signals import Segment
from cosim.subsim import ModelError, Port, Subsim

__all__ = ["ModelError", "Port", "Segment", "Subsim"]
__version__ = "0.1.0"
