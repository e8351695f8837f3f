"""Units of an SSP import: the ``Unit``/``BaseUnit`` definitions of SSP (``ssc:Unit``) and FMI
(``UnitDefinitions``), which share one form, and the affine conversion between two units they define.

A unit's value in SI base units is ``value * factor + offset`` with the SI exponents of its ``BaseUnit``;
two units convert into one another when their exponents are equal. Errors are ValueError with the reason
in words, for the SSP reader to put beside the element it came from.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class Unit:
    """A defined unit: the exponents of ``BASE`` and ``value_SI = value * factor + offset``."""

    name: str
    exponents: tuple[int, ...]
    factor: float
    offset: float

    def dimension(self) -> str:
        """The exponents as a product (``kg.m.s-2``), ``1`` for a dimensionless unit."""
        parts = [b if e == 1 else f"{b}{e}" for b, e in zip(BASE, self.exponents) if e]
        return ".".join(parts) or "1"


# x -> gain * x + offset
Affine = tuple[float, float]
IDENTITY: Affine = (1.0, 0.0)


def compose(first: Affine, then: Affine) -> Affine:
    """``then`` applied to the result of ``first``."""
    return then[0] * first[0], then[0] * first[1] + then[1]


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def unit_table(container: ET.Element | None) -> dict[str, Unit]:
    """The units defined (with a ``BaseUnit``) among the ``Unit`` children of ``container`` (an SSD's or SSV's
    ``Units``, an FMU's ``UnitDefinitions``). A ``Unit`` without ``BaseUnit`` only names a unit: it is left out."""
    table: dict[str, Unit] = {}
    for elem in container if container is not None else []:
        if _local(elem.tag) != "Unit":
            continue
        name = elem.get("name", "")
        base = next((c for c in elem if _local(c.tag) == "BaseUnit"), None)
        if base is None:
            continue
        try:
            exponents = tuple(int(base.get(b, "0")) for b in BASE)
            factor, offset = float(base.get("factor", "1")), float(base.get("offset", "0"))
        except ValueError:
            raise ValueError(f"unit {name!r}: its BaseUnit has an attribute that is not a number") from None
        if factor == 0.0:
            raise ValueError(f"unit {name!r}: its BaseUnit has factor 0")
        table[name] = Unit(name, exponents, factor, offset)
    return table


def _pair(source: str, target: str, source_units: Sequence[Mapping[str, Unit]],
          target_units: Sequence[Mapping[str, Unit]]) -> tuple[Unit, Unit]:
    found = []
    for name, tables in ((source, source_units), (target, target_units)):
        unit = next((t[name] for t in tables if name in t), None)
        if unit is None:
            raise ValueError(f"unit {name!r} has no definition (a Unit with a BaseUnit)")
        found.append(unit)
    src, dst = found
    if src.exponents != dst.exponents:
        raise ValueError(f"different dimensions ({src.name!r} is {src.dimension()}, {dst.name!r} is "
                         f"{dst.dimension()})")
    return src, dst


def conversion(source: str, target: str, source_units: Sequence[Mapping[str, Unit]],
               target_units: Sequence[Mapping[str, Unit]]) -> Affine:
    """The map from a value in ``source`` to the same quantity in ``target``, each unit looked up in its own
    tables in order (the file that names it first). Equal names need no definition. ValueError: a unit not
    defined, or the two of different dimensions."""
    if source == target:
        return IDENTITY
    src, dst = _pair(source, target, source_units, target_units)
    # value_SI = x * f_s + o_s = y * f_t + o_t, solved for y
    return src.factor / dst.factor, (src.offset - dst.offset) / dst.factor


def convert_value(value: float, source: str, target: str, source_units: Sequence[Mapping[str, Unit]],
                  target_units: Sequence[Mapping[str, Unit]]) -> float:
    """``value`` in ``source`` as a value in ``target``, through its SI value as the definitions state it (1000 g
    is exactly 1.0 kg); errors as :func:`conversion`."""
    if source == target:
        return value
    src, dst = _pair(source, target, source_units, target_units)
    return (value * src.factor + src.offset - dst.offset) / dst.factor
