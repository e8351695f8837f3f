"""Coupling transforms: vectorised maps from source signals to one input signal.

A transform is ``f(*sources, **params) -> array (n, size)`` where each source is the (n, size_i)
samples of one output over the interval. Built-ins are named; anything else is named as
``"package.module:function"`` (e.g. the satellite's frame rotations).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from cosim.importing import import_object

Transform = Callable[..., np.ndarray]


def identity(x: np.ndarray) -> np.ndarray:
    """The source signal unchanged (the default when a coupling names no transform)."""
    return x


def gain(x: np.ndarray, k: float | Sequence = 1.0) -> np.ndarray:
    """``k x`` with ``k`` a scalar or a matrix applied to every sample."""
    return _apply(np.asarray(k, dtype=float), x)


def linear(*sources: np.ndarray, gains: Sequence, offset: float | Sequence = 0.0) -> np.ndarray:
    """``sum_i gains[i] sources[i] + offset`` (each gain a scalar or a matrix)."""
    if len(gains) != len(sources):
        raise ValueError(f"linear: {len(sources)} sources need {len(sources)} gains, got {len(gains)}")
    total = sum(_apply(np.asarray(g, dtype=float), x) for g, x in zip(gains, sources))
    return total + np.asarray(offset, dtype=float)


def _apply(k: np.ndarray, x: np.ndarray) -> np.ndarray:
    if k.ndim == 0:
        return k * x
    if k.ndim == 2 and k.shape[1] == x.shape[1]:
        return x @ k.T
    if k.ndim == 1:  # (it read "gain of shape (3,) does not apply to a signal of width 3": a probe)
        raise ValueError(f"a gain is a number or a matrix (a list of rows), got a list of {k.size} numbers: for one "
                         f"gain per channel give the diagonal matrix {np.diag(k).tolist()}")
    raise ValueError(f"gain of shape {k.shape} does not apply to a signal of width {x.shape[1]}: a matrix needs "
                     f"{x.shape[1]} columns")


BUILTIN: dict[str, Transform] = {"identity": identity, "gain": gain, "linear": linear}


def resolve(name: str, search_path: Sequence[str] = ()) -> Transform:
    """A built-in name or ``"module:function"`` (``search_path``: its scenario's directories, see
    :func:`cosim.importing.import_object`); raises ValueError naming what was not found."""
    if name in BUILTIN:
        return BUILTIN[name]
    if ":" not in name:
        raise ValueError(f"unknown transform {name!r}: use one of {sorted(BUILTIN)} or 'package.module:function'")
    fn = import_object(name, "transform", search_path)
    if not callable(fn):
        raise ValueError(f"transform {name!r} is not callable")
    return fn
