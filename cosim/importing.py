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
import traceback
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
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"{what} {path!r} not found ({exc})") from None
    except Exception as exc:  # the module itself is broken (a syntax error, a NameError at import): say where
        raise ValueError(f"{what} {path!r}: importing {module_name!r} raised {_where(exc)}") from None
    try:
        return getattr(module, attr)
    except AttributeError as exc:
        raise ValueError(f"{what} {path!r} not found ({exc})") from None


def _where(exc: Exception) -> str:
    """``Type: message`` of an exception raised while importing a user's module, with the file and line it
    came from (a SyntaxError names them in its message already)."""
    if isinstance(exc, SyntaxError):
        return f"{type(exc).__name__}: {exc}"
    frames = traceback.extract_tb(exc.__traceback__)
    last = frames[-1] if frames else None
    return f"{type(exc).__name__}: {exc}" + (f" ({last.filename}, line {last.lineno})" if last else "")


def load_model(path: str) -> type[Subsim]:
    """The :class:`cosim.Subsim` subclass at ``package.module:Class``; ValueError naming the path otherwise."""
    cls = import_object(path, "model")
    if not (isinstance(cls, type) and issubclass(cls, Subsim)):
        raise ValueError(f"model {path!r} is not a cosim.Subsim subclass")
    return cls
