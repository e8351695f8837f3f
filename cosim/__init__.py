"""cosim: recursive-feedback co-simulation of stand-alone subsim processes over Eclipse Zenoh."""

from __future__ import annotations

import importlib
import warnings
from typing import TYPE_CHECKING, Any

from cosim.contract import VERSION as __version__  # noqa: F401  (the contract imports nothing: still no NumPy)

# NumPy's floating-point warnings from cosim's own arithmetic on coupled values (interpolating the inputs of a
# diverging iteration, transforming them, checking them) printed two source lines before the one-line error that
# names the signal and time, or during a run that recovered (a rejected try retried shorter).
# (appended: a user's -W error::RuntimeWarning, installed before it, still wins)
warnings.filterwarnings("ignore", r"(overflow|invalid value|divide by zero) encountered", RuntimeWarning, r"cosim\.",
                        append=True)

if TYPE_CHECKING:
    from cosim.api import run as run
    from cosim.purity import ImpureModel, check_pure
    from cosim.signals import Segment
    from cosim.subsim import IntervalTooLong, ModelError, Param, Port, Subsim

# (cosim.run: not in *)
__all__ = ["ImpureModel", "IntervalTooLong", "ModelError", "Param", "Port", "Segment", "Subsim", "check_pure"]

# Each name's module, imported on first use: ``import cosim.<anything>`` then loads no NumPy on its own (the
# ``cosim`` command answers Ctrl-C while it loads), and a subsim process never loads cosim.run's coordinator side.
_HOME = {"ImpureModel": "cosim.purity", "check_pure": "cosim.purity", "Segment": "cosim.signals",
         "ModelError": "cosim.subsim", "IntervalTooLong": "cosim.subsim", "Param": "cosim.subsim",
         "Port": "cosim.subsim", "Subsim": "cosim.subsim",
         "run": "cosim.api"}


def __getattr__(name: str) -> Any:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'cosim' has no attribute {name!r}")
    return getattr(importlib.import_module(home), name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOME))
