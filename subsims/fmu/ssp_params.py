"""Parameter bindings of an SSP (``ParameterBinding``): the value each FMU variable is given.

A binding's parameter set (an ``.ssv`` file in the archive, or inline ``ParameterValues``) names values. As SSP
says, the binding's ``prefix`` is put before every name of the set, then its ``ParameterMapping`` (an ``.ssm`` file
in the archive, or inline) may rename a name (``MappingEntry`` source -> target) and transform its value (a
``LinearTransformation``, or a table of booleans or integers); a name no entry lists stays as it is. A Real given
in a ``unit`` is converted to the unit of the variable it sets, before a linear transformation (not at all with
the entry's ``suppressUnitConversion``), as on connections.

A binding on a component names that FMU's variables; one on the system names ``<component>.<variable>``. Among
the bindings of one element the later ones win; the system's win over the components' (SSP's precedence).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import PurePosixPath
from typing import Any

from cosim.scenario import ScenarioError
from subsims.fmu.ssp_units import Unit, convert_value, unit_table

REAL_KINDS = {"Real", "Float64", "Float32"}
MAPPING_TYPE = "application/x-ssp-parameter-mapping"
VALUE_TABLES = {"BooleanMappingTransformation", "IntegerMappingTransformation"}


def local(tag: str) -> str:
    """An XML tag without its namespace."""
    return tag.rsplit("}", 1)[-1]


def children(elem: ET.Element, name: str) -> list[ET.Element]:
    return [c for c in elem if local(c.tag) == name]


def child(elem: ET.Element, name: str) -> ET.Element | None:
    found = children(elem, name)
    return found[0] if found else None


def inner(elem: ET.Element, name: str) -> list[ET.Element]:
    """The children of ``elem``'s child ``name`` (none if it has no such child)."""
    found = child(elem, name)
    return list(found) if found is not None else []


@dataclass
class Variables:
    """What the import knows of a component's FMU (its modelDescription.xml): the unit of each variable ('' for
    none), the units it defines, and the interfaces it describes (CoSimulation, ModelExchange)."""

    units: dict[str, str] = field(default_factory=dict)
    defined: dict[str, Unit] = field(default_factory=dict)
    interfaces: set[str] = field(default_factory=set)


# a name the binding gives a value -> (component, its FMU's variables or None if unreadable, variable name)
Resolver = Callable[[str], tuple[str, Variables | None, str]]


@dataclass(frozen=True)
class _Entry:
    """One ``MappingEntry``: the variable it sets, whether units are left unconverted, its transformation."""

    target: str
    suppress: bool
    transform: ET.Element | None


def binding_values(binding: ET.Element, zf: zipfile.ZipFile, where: str, ssd_units: dict[str, Unit],
                   resolve: Resolver) -> list[tuple[str, str, Any]]:
    """(component, variable, value) of every parameter the binding sets, in the order of its parameter set."""
    found = _parameter_set(binding, zf, where)
    if found is None:
        return []
    root, label = found
    try:
        own_units = unit_table(child(root, "Units"))
    except ValueError as exc:
        raise ScenarioError(f"{where}: parameter set {label}: {exc}") from None
    mapping = _mapping(binding, zf, where)
    prefix = binding.get("prefix", "")
    out = []
    for params in children(root, "Parameters"):
        for param in children(params, "Parameter"):
            name = prefix + param.get("name", "")
            value, unit = _value(param, name, where)
            entry = mapping.get(name)
            target = entry.target if entry is not None else name
            component, variables, variable = resolve(target)
            if unit is not None and not (entry is not None and entry.suppress) and variables is not None \
                    and variable in variables.units:
                value = _in_variable_unit(value, unit, variable, variables, [own_units, ssd_units], where)
            if entry is not None and entry.transform is not None:
                value = _transformed(value, entry.transform, f"{where}: parameter {name!r} mapped to {target!r}")
            out.append((component, variable, value))
    return out


def _parameter_set(binding: ET.Element, zf: zipfile.ZipFile, where: str) -> tuple[ET.Element, str] | None:
    """The binding's ``ParameterSet`` element and how to name it (its file, or ``(inline)``); None: no values."""
    source = binding.get("source")
    if source is None:
        values = child(binding, "ParameterValues")
        root = child(values, "ParameterSet") if values is not None else None
        return (root, "(inline)") if root is not None else None
    return _archived(binding, source, zf, where, "parameter file"), repr(source)


def _archived(elem: ET.Element, source: str, zf: zipfile.ZipFile, where: str, what: str) -> ET.Element:
    """The root element of the XML file ``source`` of ``elem`` (a binding or its mapping) in the SSP archive."""
    if source.startswith("#"):
        raise ScenarioError(f"{where}: references to elements of the SSD ({what} {source!r}) are not supported")
    if elem.get("sourceBase", "SSD") != "SSD":
        raise ScenarioError(f"{where}: a {what} inside the component's FMU (sourceBase={elem.get('sourceBase')!r}, "
                            f"{source!r}) is not supported; put it in the SSP archive")
    try:
        return ET.fromstring(zf.read(str(PurePosixPath(source))))
    except KeyError:
        raise ScenarioError(f"{where}: {what} {source!r} is not in the archive") from None
    except ET.ParseError as exc:
        raise ScenarioError(f"{where}: {what} {source!r} is not valid XML ({exc})") from None


def _mapping(binding: ET.Element, zf: zipfile.ZipFile, where: str) -> dict[str, _Entry]:
    """The binding's ``ParameterMapping`` (a file, or inline): source name -> its entry; empty without one."""
    elem = child(binding, "ParameterMapping")
    if elem is None:
        return {}
    if elem.get("type", MAPPING_TYPE) != MAPPING_TYPE:
        raise ScenarioError(f"{where}: parameter mapping of type {elem.get('type')!r} is not supported (only "
                            f"{MAPPING_TYPE!r}, SSP's .ssm)")
    source = elem.get("source")
    label = repr(source) if source else "(inline)"
    root = _archived(elem, source, zf, where, "parameter mapping") if source else child(elem, "ParameterMapping")
    if root is None:
        return {}
    if local(root.tag) != "ParameterMapping":
        raise ScenarioError(f"{where}: parameter mapping {label} is no ParameterMapping (its root is "
                            f"{local(root.tag)})")
    entries: dict[str, _Entry] = {}
    for entry in children(root, "MappingEntry"):
        src, dst = entry.get("source"), entry.get("target")
        if not src or not dst:
            raise ScenarioError(f"{where}: parameter mapping {label}: a MappingEntry without source or target "
                                f"(source={src!r}, target={dst!r})")
        if src in entries:
            raise ScenarioError(f"{where}: parameter mapping {label} maps {src!r} twice")
        transforms = [c for c in entry if local(c.tag) != "Annotations"]
        for t in transforms:
            if local(t.tag) != "LinearTransformation" and local(t.tag) not in VALUE_TABLES:
                raise ScenarioError(f"{where}: parameter mapping {label}, entry {src!r}: {local(t.tag)} is not "
                                    "supported (LinearTransformation, BooleanMappingTransformation and "
                                    "IntegerMappingTransformation are)")
        entries[src] = _Entry(dst, entry.get("suppressUnitConversion", "false") in {"true", "1"},
                              transforms[0] if transforms else None)
    return entries


def _transformed(value: Any, transform: ET.Element, where: str) -> Any:
    """``value`` through a mapping entry's transformation."""
    kind = local(transform.tag)
    if kind == "LinearTransformation":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{where}: a LinearTransformation takes a number, the value is {value!r}")
        try:
            factor, offset = float(transform.get("factor", 1.0)), float(transform.get("offset", 0.0))
        except ValueError:
            raise ScenarioError(f"{where}: bad LinearTransformation (factor {transform.get('factor')!r}, offset "
                                f"{transform.get('offset')!r})") from None
        mapped = factor * value + offset
        return int(mapped) if type(value) is int and mapped.is_integer() else mapped  # (an Integer stays one)
    parse = _boolean if kind == "BooleanMappingTransformation" else int
    table = {}
    for entry in children(transform, "MapEntry"):
        try:
            table[parse(entry.get("source", ""))] = parse(entry.get("target", ""))
        except ValueError:
            raise ScenarioError(f"{where}: {kind}: bad MapEntry (source {entry.get('source')!r}, target "
                                f"{entry.get('target')!r})") from None
    if type(value) is not type(next(iter(table), value)) or value not in table:
        raise ScenarioError(f"{where}: its {kind} has no MapEntry for the value {value!r} (sources: "
                            f"{sorted(table)})")
    return table[value]


def _boolean(raw: str) -> bool:
    if raw not in {"true", "false", "1", "0"}:
        raise ValueError(raw)
    return raw in {"true", "1"}


def _value(param: ET.Element, name: str, where: str) -> tuple[Any, str | None]:
    """The parameter's value and the unit it is given in (a Real's ``unit``; None: the variable's own)."""
    for typed in param:
        kind, raw = local(typed.tag), typed.get("value")
        if raw is None:
            continue
        try:
            if kind in REAL_KINDS:
                return float(raw), typed.get("unit") or None
            if kind == "Enumeration":  # SSP gives an item by its name; the FMU subsim takes it so, or its number
                return (int(raw) if raw.lstrip("+-").isdigit() else raw), None
            if kind == "Integer" or kind.startswith(("Int", "UInt")):
                return int(raw), None
            if kind == "Boolean":
                return _boolean(raw), None
            if kind == "String":
                return raw, None
        except ValueError:
            raise ScenarioError(f"{where}: parameter {name!r}: bad {kind} value {raw!r}") from None
    raise ScenarioError(f"{where}: parameter {name!r} has no Real/Integer/Boolean/String value")


def _in_variable_unit(value: float, unit: str, name: str, variables: Variables, units: list[dict[str, Unit]],
                      where: str) -> float:
    """SSP: a value with a unit is in that unit, the FMU takes it in its variable's."""
    target = variables.units[name]
    if not target:
        raise ScenarioError(f"{where}: parameter {name!r} is given in {unit!r} but FMU variable {name!r} declares "
                            "no unit: give the value in the unit the FMU expects, without a unit attribute")
    try:  # the parameter's unit is defined in its parameter set or the SSD (else the FMU), the variable's in the FMU
        # (else the SSD, else the parameter set: an FMU may name its units without defining them)
        return convert_value(value, unit, target, [*units, variables.defined], [variables.defined, *reversed(units)])
    except ValueError as exc:
        raise ScenarioError(f"{where}: parameter {name!r} is given in {unit!r} and FMU variable {name!r} is in "
                            f"{target!r}: cannot convert, {exc}") from None
