"""Resolve ``"package.module:name"`` strings (models, transforms, unified references)."""

from __future__ import annotations

import importlib
from typing import Any

from cosim.subsim import Subsim


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
