"""Resolve ``"package.module:name"`` strings (models, transforms, unified references).

A scenario names the user's own modules: :func:`add_search_path` puts the scenario file's
directory and the working directory on the import path (at its end, so they never shadow an
installed package), and :data:`SEARCH_PATH` lists what was added so that ``cosim.launch`` hands the
same directories to the subsim processes it starts (through their ``PYTHONPATH``).
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path
from typing import Any

from cosim.subsim import Subsim

SEARCH_PATH: list[str] = []  # directories add_search_path put on sys.path, in order


def add_search_path(*directories: str | Path) -> None:
    """Append each directory (made absolute) to ``sys.path`` and :data:`SEARCH_PATH`, once."""
    for d in directories:
        path = os.path.abspath(d)
        if path not in SEARCH_PATH:
            SEARCH_PATH.append(path)
        if path not in sys.path:
            sys.path.append(path)
            importlib.invalidate_caches()


def import_object(path: str, what: str) -> Any:
    """The object ``name`` of ``package.module``; ValueError naming ``what`` and the path otherwise."""
    module_name, sep, attr = str(path).partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"{what} {path!r} must be 'package.module:name'")
    try:
        return getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"{what} {path!r} not found ({exc})") from None


def load_model(path: str) -> type[Subsim]:
    """The :class:`cosim.Subsim` subclass at ``package.module:Class``; ValueError naming the path otherwise."""
    cls = import_object(path, "model")
    if not (isinstance(cls, type) and issubclass(cls, Subsim)):
        raise ValueError(f"model {path!r} is not a cosim.Subsim subclass")
    return cls
