"""Couplings (output signals -> one input signal) and the graph they make between subsims."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from difflib import get_close_matches
from inspect import signature
from pathlib import PurePath
from typing import Any

import numpy as np

from cosim.importing import own_frame
from cosim.transforms import BUILTIN, Transform, identity, resolve

_F8 = np.dtype(np.float64)

Signals = Mapping[str, Mapping[str, np.ndarray]]  # subsim -> port -> samples (n, size)


@dataclass(frozen=True)
class SignalRef:
    subsim: str
    port: str

    @classmethod
    def parse(cls, text: str) -> SignalRef:
        if not isinstance(text, str):
            raise ValueError(f"signal {text!r} must be a string 'subsim.port'")
        subsim, dot, port = text.partition(".")
        if not dot or not subsim or not port:
            raise ValueError(f"signal {text!r} must be written 'subsim.port'")
        return cls(subsim, port)

    def __str__(self) -> str:
        return f"{self.subsim}.{self.port}"


@dataclass(frozen=True)
class Coupling:
    """``target = transform(*sources, **params)``, evaluated sample by sample over an interval."""

    target: SignalRef
    sources: tuple[SignalRef, ...]
    transform: Transform = identity
    params: Mapping[str, Any] = field(default_factory=dict)
    transform_name: str = "identity"

    @classmethod
    def make(
        cls, target: str, sources: str | Sequence[str], transform: str = "identity", params: Mapping | None = None,
        search_path: Sequence[str] = (),
    ) -> Coupling:
        """``search_path``: the directories of the scenario that names a ``module:function`` transform."""
        srcs = (sources,) if isinstance(sources, str) else tuple(sources)
        if not srcs:
            raise ValueError(f"coupling to {target!r} has no source")
        return cls(
            SignalRef.parse(target), tuple(SignalRef.parse(s) for s in srcs), resolve(transform, search_path),
            dict(params or {}), transform,
        )

    def evaluate(self, outputs: Signals, size: int, n: int) -> np.ndarray:
        """The target's samples (n, size) from the sources' samples in ``outputs``. TransformError in one line."""
        args = [outputs[s.subsim][s.port] for s in self.sources]
        try:
            value = self.transform(*args, **self.params)
            if type(value) is not np.ndarray or value.dtype != _F8:
                value = np.asarray(value, dtype=np.float64)
        except Exception as exc:
            raise TransformError(f"coupling {self}: transform {self.transform_name!r} failed: {exc} "
                                 f"({type(exc).__name__}{_raised_at(exc)})") from exc
        if value.shape != (n, size) and value.shape == (n,) and size == 1:  # as a model's (n,) output is taken
            value = value.reshape(n, 1)
        if value.shape != (n, size):
            name = self.transform_name
            raise TransformError(f"coupling {self}: transform {name!r} gave shape {value.shape}, need ({n}, {size})")
        if np.count_nonzero(np.isfinite(value)) != value.size:  # not .all(): its Python wrapper costs more
            largest = max((float(np.max(np.abs(a), initial=0.0)) for a in args), default=0.0)  # (NaN: not finite)
            if not largest <= HUGE:
                raise TransformError(f"coupling {self}: transform {self.transform_name!r} produced NaN or inf (as a "
                                     "coupling iteration that diverges makes them: a shorter [coupling] interval "
                                     f"then; its sources reached {largest:.3g})")
            raise TransformError(f"coupling {self}: transform {self.transform_name!r} produced NaN or inf from "
                                 f"finite sources of at most {largest:.3g} in size: its own arithmetic (a division "
                                 "by zero?)")
        return value

    def as_table(self) -> dict[str, Any]:
        """The coupling as a scenario's ``[[couplings]]`` table."""
        return {"to": str(self.target), "from": [str(s) for s in self.sources], "transform": self.transform_name,
                "params": dict(self.params)}

    def __str__(self) -> str:
        return f"{', '.join(map(str, self.sources))} -> {self.target}"


Ports = Mapping[str, Mapping[str, int]]  # subsim -> port -> width
HUGE = 1e100  # sources this large made a transform's NaN or inf: a diverging iteration (subsims' outputs are finite)


def _raised_at(exc: BaseException) -> str:
    """`` at file.py:12``: where in a transform's own code ``exc`` came from (not NumPy's fromnumeric.py)."""
    frame = own_frame(exc)
    return f" at {PurePath(frame.filename).name}:{frame.lineno}" if frame is not None else ""


class TransformError(ValueError):
    """A coupling's transform failed on a stage's samples, or gave the wrong shape or a NaN: one line."""


class CouplingError(ValueError):
    """A coupling does not fit the subsims' ports; ``index`` is its position in the list."""

    def __init__(self, index: int, message: str) -> None:
        super().__init__(message)
        self.index = index


Units = Mapping[str, Mapping[str, str]]  # subsim -> port -> unit ("": not declared)


def check_couplings(couplings: Sequence[Coupling], inputs: Ports, outputs: Ports) -> None:
    """Every source is an existing output, every target an existing input driven at most once,
    and an identity coupling joins signals of equal size. Raises CouplingError naming the coupling."""
    driven: dict[SignalRef, Coupling] = {}
    for i, c in enumerate(couplings):
        try:
            _check_one(c, inputs, outputs, driven)
        except ValueError as exc:
            raise CouplingError(i, str(exc)) from None


def _check_one(c: Coupling, inputs: Ports, outputs: Ports, driven: dict[SignalRef, Coupling]) -> None:
    if c.target.subsim not in inputs:
        raise ValueError(f"coupling {c}: unknown subsim {c.target.subsim!r}")
    if c.target.port not in inputs[c.target.subsim]:
        known = ", ".join(inputs[c.target.subsim]) or "none"
        swap = _reversed(c, c.target.port in outputs.get(c.target.subsim, {}), "an output")
        raise ValueError(f"coupling {c}: {c.target.subsim!r} has no input {c.target.port!r} (inputs: {known}){swap}")
    for s in c.sources:
        if s.subsim not in outputs:
            raise ValueError(f"coupling {c}: unknown subsim {s.subsim!r}")
        if s.port not in outputs[s.subsim]:
            known = ", ".join(outputs[s.subsim]) or "none"
            swap = _reversed(c, s.port in inputs.get(s.subsim, {}), "an input")
            raise ValueError(f"coupling {c}: {s.subsim!r} has no output {s.port!r} (outputs: {known}){swap}")
    if c.target in driven:
        raise ValueError(f"input {c.target} is driven twice: by {driven[c.target]} and by {c}; to add them, give "
                         f"one coupling every source in its from, with transform = \"linear\" (params = {{ gains = "
                         "[...] }) or a function of your own")
    driven[c.target] = c
    if c.transform is identity:
        if len(c.sources) != 1:
            raise ValueError(f"coupling {c}: several sources need a transform")
        src, dst = outputs[c.sources[0].subsim][c.sources[0].port], inputs[c.target.subsim][c.target.port]
        if src != dst:
            raise ValueError(f"coupling {c}: size mismatch, output has {src}, input takes {dst}")
        return
    _try_transform(c, inputs, outputs)


def _reversed(c: Coupling, other_kind: bool, kind: str) -> str:
    """The hint for a port named on the wrong side of a coupling (to = an output, from = an input: a probe)."""
    return f"; it is {kind} there: are to and from swapped?" if other_kind else ""


def check_units(couplings: Sequence[Coupling], inputs: Units, outputs: Units) -> None:
    """An identity coupling joins ports of the same unit where both declare one (a transform may convert, so its
    ports are not compared). Units are compared as written: 'rad/s' and 'deg/s' differ, so do 'm/s' and 'm s^-1'.
    A product may be written with a space, '*', '.' or a dot ('N m' is 'N*m'), a quotient with or without spaces.
    Raises CouplingError naming the first such coupling, and the others after it (one run to see them all)."""
    bad = []
    for i, c in enumerate(couplings):
        if c.transform is not identity:
            continue
        src = outputs[c.sources[0].subsim][c.sources[0].port]
        dst = inputs[c.target.subsim][c.target.port]
        if src and dst and _unit(src) != _unit(dst):
            bad.append((i, f"coupling {c}: units differ, the output is in {src!r} and the input takes {dst!r}"))
    if bad:
        others = "".join(f"; also [couplings[{i}]] {text}" for i, text in bad[1:])
        first = couplings[bad[0][0]]
        ends = {_unit(outputs[first.sources[0].subsim][first.sources[0].port]),
                _unit(inputs[first.target.subsim][first.target.port])}
        scales = {OFFSET_UNITS.get(unit) for unit in ends}
        convert = ("transform = \"linear\", params = { gains = [1.0], offset = ... }: a scale with an offset, "
                   "K = degC + 273.15" if None not in scales and len(scales) == 2 else
                   "transform = \"gain\", params = { k = ... }")
        raise CouplingError(bad[0][0], f"{bad[0][1]}: if it is one quantity in two units, convert with a transform "
                            f"({convert}) or declare the ports in one unit; if not, the coupling joins the wrong "
                            f"ports{others}")


# temperature scales with an offset between them: a gain alone does not convert them (a legacy-code probe)
OFFSET_UNITS = {"K": "K", "degC": "C", "\u00b0C": "C", "degF": "F", "\u00b0F": "F", "degR": "R",
                "\u00b0R": "R"}  # unit -> its scale (not C or F alone: coulomb, farad)


def _unit(text: str) -> str:
    """A unit as compared: the product signs written alike."""
    for product in ("*", "\u00b7", "\u22c5", "."):
        text = text.replace(product, " ")
    return "/".join(" ".join(part.split()) for part in text.split("/"))


def _try_transform(c: Coupling, inputs: Ports, outputs: Ports) -> None:
    """Call the transform once on samples of the sources' sizes (all ones), before any run: wrong parameters
    and a result of the wrong width show here. A user's transform may also fail for reasons that depend on the
    values, which only a run has: of its errors only a TypeError (a parameter it does not take or lacks) counts."""
    args = [np.ones((2, outputs[s.subsim][s.port])) for s in c.sources]
    size = inputs[c.target.subsim][c.target.port]
    try:
        value = c.transform(*args, **c.params)
    except Exception as exc:
        if isinstance(exc, TypeError) or c.transform in BUILTIN.values():
            raise ValueError(f"coupling {c}: transform {c.transform_name!r}: {exc}{_takes(c, exc)}") from None
        return
    shape = np.shape(value)
    if shape != (2, size) and not (shape == (2,) and size == 1):  # (flat samples of a 1-wide input: evaluate takes)
        widths = ", ".join(f"{s} ({outputs[s.subsim][s.port]} wide)" for s in c.sources)
        raise ValueError(f"coupling {c}: transform {c.transform_name!r} turns 2 samples of {widths} into shape "
                         f"{shape}; input {c.target} takes {size} per sample: (2, {size})")


def _takes(c: Coupling, exc: BaseException) -> str:
    """For a parameter the transform does not take: the one it takes that is close, and what it takes."""
    unknown = re.search(r"unexpected keyword argument '([^']+)'", str(exc))
    try:
        names = [p.name for p in signature(c.transform).parameters.values() if p.kind is p.KEYWORD_ONLY
                 or (p.kind is p.POSITIONAL_OR_KEYWORD and p.default is not p.empty)]
    except (TypeError, ValueError):  # no signature to read (a builtin)
        return ""
    if unknown is None or not names:
        return ""
    close = get_close_matches(unknown.group(1), names, n=1) or [n for n in names if n.lower() == unknown.group(1)
                                                                 .lower()]
    return (f" (did you mean {close[0]!r}?)" if close else "") + f"; it takes: {', '.join(names)}"


def feedback_weight(order: Sequence[str], couplings: Sequence[Coupling], sizes: Mapping[SignalRef, int]) -> int:
    """Scalar signals that cross the recursive transfer point when subsims run in ``order``."""
    rank = {name: i for i, name in enumerate(order)}
    return sum(sizes[c.target] for c in couplings if is_feedback(c, rank))


def is_feedback(c: Coupling, rank: Mapping[str, int]) -> bool:
    """A coupling runs backwards when some source runs at or after its target."""
    return any(rank[s.subsim] >= rank[c.target.subsim] for s in c.sources)
