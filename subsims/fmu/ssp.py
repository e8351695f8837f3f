"""SSP import and the ``fmu = "path.fmu"`` scenario shorthand: both produce the raw scenario dict a
scenario TOML parses to, so ``cosim.scenario.parse`` checks them like any scenario.

``read_ssp("system.ssp")`` reads ``SystemStructure.ssd`` from the SSP archive (System Structure and
Parameterization 1.0/2.0): every FMU component becomes a subsim (its FMU extracted to a directory that
lives as long as this process; its ``implementation`` chooses the subsim's ``interface``), every
connection a coupling (a ``LinearTransformation`` and a conversion between the units of its ends become
the ``linear`` transform), parameter bindings of components and of the system (``subsims/fmu/ssp_params.py``:
parameter sets, prefixes, parameter mappings, units) become params, and ``DefaultExperiment`` gives
start and stop. Units are defined as in SSP and FMI (``Unit`` with ``BaseUnit``): in the SSD's or the
parameter set's ``Units``, or the FMU's ``UnitDefinitions``. A companion ``system.toml`` beside
``system.ssp`` may add or override the top-level scenario tables (``stop``, ``[coupling]`` with method,
interval, samples, tol ..., ``[tolerances]``, ``[output]``) and per-subsim params
(``[subsims.<name>.params]``).
Not supported (refused with the element named): nested systems, system-level connectors, signal
dictionaries, components that are not FMUs, transformations other than linear ones on connections,
references to SSD elements, units that cannot be converted (not defined, or of different dimensions) where a
conversion is needed.
"""

from __future__ import annotations

import io
import re
import tempfile
import tomllib
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path, PurePosixPath
from typing import Any

from cosim.scenario import ScenarioError, check_subsim_name
from subsims.fmu.scratch import process_dir
from subsims.fmu.ssp_params import REAL_KINDS, Variables, binding_values, child, inner, local
from subsims.fmu.ssp_units import IDENTITY, Affine, Unit, compose, conversion, unit_table

MODEL = "subsims.fmu:FmuSubsim"
FMU_TYPES = {"application/x-fmu-sharedlibrary", None}
LAYOUT_ONLY = {"ConnectionGeometry", "Annotations"}  # children of a Connection that carry no coupling
COMPANION_KEYS = {"name", "description", "start", "stop", "coupling", "tolerances", "output", "subsims"}
IMPLEMENTATIONS = {"any": None, "CoSimulation": "cs", "ModelExchange": "me"}  # -> the FMU subsim's interface


def expand_fmu(spec: Mapping[str, Any], scenario: Path, start: float, key: str) -> dict[str, Any]:
    """``[subsims.<name>]`` with ``fmu = "path.fmu"`` as the table it stands for: ``model`` is the FMU subsim,
    ``params.fmu`` the path resolved against the scenario file's directory (as given, for a subsim with a
    ``launcher``: a path on its machine), ``params.start_time`` the start."""
    table = dict(spec)
    fmu = table.pop("fmu")
    if "model" in table:
        raise ScenarioError(f"{scenario}: [{key}] give fmu or model, not both")
    if not isinstance(fmu, str) or not fmu:
        raise ScenarioError(f"{scenario}: [{key}.fmu] must be the path of an .fmu file, got {fmu!r}")
    params = table.get("params", {})
    if not isinstance(params, dict):
        raise ScenarioError(f"{scenario}: [{key}.params] must be a table")
    if "fmu" in params:  # (params.fmu was dropped for fmu = ... without a word: an FMI probe)
        raise ScenarioError(f"{scenario}: [{key}] names its FMU twice, fmu = {fmu!r} and params.fmu = "
                            f"{params['fmu']!r}: give fmu = ... only")
    if "launcher" in table:  # started on another machine: a path there, relative to its workdir
        params = {**params, "fmu": fmu}
    else:
        resolved = (scenario.parent / fmu).resolve()
        if not table.get("external", False) and not resolved.is_file():  # launched here: a typo, found at load
            what = "a directory, not an .fmu file" if resolved.is_dir() else "no such file"
            raise ScenarioError(f"{scenario}: [{key}.fmu] {what}: {resolved}")
        if not table.get("external", False):  # a broken file is its fmu = line's fault, said at load (it came as
            from subsims.fmu.fmu import FmuError, read_fmu  # "[...params] configure: bad parameter": an FMI probe)

            try:
                read_fmu(resolved)
            except FmuError as exc:
                raise ScenarioError(f"{scenario}: [{key}.fmu] {exc}") from None
        params = {**params, "fmu": str(resolved)}
    if start != 0.0:
        params.setdefault("start_time", start)
    return {**table, "model": MODEL, "params": params}


def _extract_dir() -> Path:
    return Path(tempfile.mkdtemp(dir=process_dir("cosim-ssp-")))


def _read_model(data: bytes) -> Variables | None:
    """The FMU's :class:`Variables`; None when it cannot be read (the subsim's configure says why, in its words)."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as fmu:
            root = ET.fromstring(fmu.read("modelDescription.xml"))
    except (zipfile.BadZipFile, KeyError, ET.ParseError):
        return None
    declared = {}  # type name -> unit; FMI 2 wraps the type (SimpleType/Real), FMI 3 does not (Float64Type)
    for typedef in inner(root, "TypeDefinitions"):
        typed = typedef[0] if local(typedef.tag) == "SimpleType" and len(typedef) else typedef
        declared[typedef.get("name", "")] = typed.get("unit", "")
    model = Variables(interfaces={local(c.tag) for c in root} & {"CoSimulation", "ModelExchange"})
    for var in inner(root, "ModelVariables"):
        typed = var[0] if local(var.tag) == "ScalarVariable" and len(var) else var
        model.units[var.get("name", "")] = typed.get("unit") or declared.get(typed.get("declaredType", ""), "")
    try:
        model.defined = unit_table(child(root, "UnitDefinitions"))
    except ValueError:
        return None  # a broken description: configure refuses the FMU
    return model


@dataclass
class _End:
    """A component as a connection's end: its FMU's :class:`Variables` (None: unreadable) and the units its SSD
    connectors declare (None: the FMU variable's)."""

    model: Variables | None
    connectors: dict[str, str | None]

    def units(self, connector: str) -> tuple[str, str]:
        """(the FMU variable's unit, the connector's unit), '' where none is known."""
        fmu = self.model.units.get(connector, "") if self.model is not None else ""
        return fmu, self.connectors.get(connector) or fmu


def _bind(params: dict[str, Any], variable: str, value: Any) -> None:
    """An FMU variable's value in the FMU subsim's params: by its name, or in its ``values`` table where the name is
    also one of the subsim's own settings (a variable named ``rtol`` must not set the solver's: a review)."""
    from subsims.fmu.subsim import SETTINGS  # (the subsim module imports SciPy: only for an SSP)

    if variable in SETTINGS:
        params.setdefault("values", {})[variable] = value
    else:
        params[variable] = value


def _bindings(element: ET.Element) -> list[ET.Element]:
    return [b for b in inner(element, "ParameterBindings") if local(b.tag) == "ParameterBinding"]


def _in_system(ends: dict[str, _End], where: str, name: str) -> tuple[str, Variables | None, str]:
    """A name in a system's parameter set, ``<component>.<variable>``, as that component's variable."""
    component, dot, variable = name.partition(".")  # (a component's name has no dot; a variable's may)
    if not dot or not variable or component not in ends:
        raise ScenarioError(f"{where}: parameter {name!r} names no component's variable (a system's parameters are "
                            f"named <component>.<variable>; components: {sorted(ends)})")
    return component, ends[component].model, variable


def _connector_unit(connector: ET.Element) -> str | None:
    typed = next((t for t in connector if local(t.tag) in REAL_KINDS), None)
    return typed.get("unit") if typed is not None else None


def _interface(comp: ET.Element, model: Variables | None, where: str, source: str) -> str | None:
    """The FMU subsim's ``interface`` for the component's ``implementation`` (None: the subsim's default)."""
    implementation = comp.get("implementation", "any")
    if implementation not in IMPLEMENTATIONS:
        raise ScenarioError(f"{where}: implementation {implementation!r} is not one of {sorted(IMPLEMENTATIONS)}")
    if model is not None and IMPLEMENTATIONS[implementation] is not None and implementation not in model.interfaces:
        offered = " and ".join(sorted(model.interfaces)) or "no interface"
        raise ScenarioError(f"{where}: implementation {implementation!r}, but its FMU {source!r} offers {offered}")
    return IMPLEMENTATIONS[implementation]


def _coupling(conn: ET.Element, ends: dict[str, _End], ssd_units: dict[str, Unit], where: str,
              system: str) -> dict[str, Any]:
    """The coupling of a connection: from the start FMU's output to the end FMU's input, through each unit on the
    way (FMU variable, connector, connector, FMU variable) and the LinearTransformation, which SSP applies to the
    value already converted to the end connector's unit (before it unless suppressUnitConversion)."""
    names = [conn.get(a) for a in ("startElement", "startConnector", "endElement", "endConnector")]
    text = f"{names[0] or system}.{names[1]} -> {names[2] or system}.{names[3]}"
    if not names[0] or not names[2]:
        raise ScenarioError(f"{where} {text}: system-level connectors are not supported")
    coupling: dict[str, Any] = {"to": f"{names[2]}.{names[3]}", "from": f"{names[0]}.{names[1]}"}
    linear: Affine | None = None
    for transform in conn:
        if local(transform.tag) in LAYOUT_ONLY:  # where an editor drew the line: nothing to couple
            continue
        if local(transform.tag) != "LinearTransformation":
            raise ScenarioError(f"{where} {text}: {local(transform.tag)} is not supported")
        try:
            linear = float(transform.get("factor", 1.0)), float(transform.get("offset", 0.0))
        except ValueError:
            raise ScenarioError(f"{where} {text}: bad LinearTransformation") from None
    suppress = conn.get("suppressUnitConversion", "false") in {"true", "1"}
    start, end = ends.get(names[0]), ends.get(names[2])
    out_fmu, out_conn = start.units(names[1]) if start is not None else ("", "")
    in_fmu, in_conn = end.units(names[3]) if end is not None else ("", "")
    out_defs = [start.model.defined] if start is not None and start.model is not None else []
    in_defs = [end.model.defined] if end is not None and end.model is not None else []
    chain = _between(out_fmu, out_conn, [*out_defs, ssd_units], [ssd_units, *out_defs], True,
                     f"{where} {text}: connector {names[0]}.{names[1]}")
    if out_conn and in_conn and not suppress:
        try:
            chain = compose(chain, conversion(out_conn, in_conn, [ssd_units, *out_defs], [ssd_units, *in_defs]))
        except ValueError as exc:
            if linear is None:  # nothing says how one becomes the other; with a transformation, it does
                raise ScenarioError(f"{where} {text}: the output is in {out_conn!r} and the input in {in_conn!r}: "
                                    f"cannot convert, {exc}; connect ports of one quantity, or give the connection "
                                    "a LinearTransformation that maps one to the other") from None
    if linear is not None:
        chain = compose(chain, linear)
    chain = compose(chain, _between(in_fmu, in_conn, [*in_defs, ssd_units], [ssd_units, *in_defs], False,
                                    f"{where} {text}: connector {names[2]}.{names[3]}"))
    # an identity coupling keeps the run's unit check; one the SSP asks not to convert is the user's word
    differ = suppress and bool(out_conn) and bool(in_conn) and out_conn != in_conn
    if linear is not None or chain != IDENTITY or differ:
        coupling.update(transform="linear", params={"gains": [chain[0]], "offset": chain[1]})
    return coupling


def _between(variable: str, connector: str, variable_units: list[dict[str, Unit]],
             connector_units: list[dict[str, Unit]], outward: bool, where: str) -> Affine:
    """An FMU variable's value in its connector's unit (``outward``: an output) or the reverse (an input), when the
    SSD declares the connector in another unit than the FMU's."""
    if not variable or not connector:
        return IDENTITY
    try:
        if outward:
            return conversion(variable, connector, variable_units, connector_units)
        return conversion(connector, variable, connector_units, variable_units)
    except ValueError as exc:
        raise ScenarioError(f"{where}: the connector is declared in {connector!r} and its FMU variable is in "
                            f"{variable!r}: cannot convert, {exc}") from None


def read_ssp(path: str | Path) -> dict[str, Any]:
    """The raw scenario dict of an SSP file (and its companion TOML, if any); ScenarioError naming what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"SSP file {path} not found")
    if not zipfile.is_zipfile(path):
        raise ScenarioError(f"{path}: not an SSP file (not a zip archive)")
    with zipfile.ZipFile(path) as zf:
        try:
            root = ET.fromstring(zf.read("SystemStructure.ssd"))
        except KeyError:
            raise ScenarioError(f"{path}: not an SSP file (no SystemStructure.ssd in the archive)") from None
        except ET.ParseError as exc:
            raise ScenarioError(f"{path}: SystemStructure.ssd is not valid XML ({exc})") from None
        system = child(root, "System")
        if system is None:
            raise ScenarioError(f"{path}: SystemStructure.ssd has no System")
        # (the name names the default results file: a tool's "Plant/Controller" must not make it a path)
        name = re.sub(r"[/\\\0]", "_", root.get("name") or "").strip(" .") or path.stem
        raw: dict[str, Any] = {"name": name, "subsims": {}, "couplings": []}
        experiment = child(root, "DefaultExperiment")
        if experiment is not None:
            for attr, key in (("startTime", "start"), ("stopTime", "stop")):
                if experiment.get(attr) is not None:
                    try:
                        raw[key] = float(experiment.get(attr))
                    except ValueError:
                        raise ScenarioError(f"{path}: DefaultExperiment {attr} is not a number") from None
        system_name = system.get("name") or "(unnamed)"
        if child(system, "SignalDictionaries") is not None:  # its entries' units and types would go unread
            raise ScenarioError(f"{path}: system {system_name!r}: signal dictionaries (SignalDictionaries) are not "
                                "supported; connect the components' connectors directly")
        try:
            ssd_units = unit_table(child(root, "Units"))
        except ValueError as exc:
            raise ScenarioError(f"{path}: SystemStructure.ssd Units: {exc}") from None
        target = _extract_dir()
        ends: dict[str, _End] = {}
        for comp in inner(system, "Elements"):
            kind = local(comp.tag)
            name = comp.get("name", "")
            where = f"{path}: component {name!r}"
            if kind == "System":
                raise ScenarioError(f"{path}: nested system {name!r} is not supported (flatten it)")
            if kind != "Component":
                raise ScenarioError(f"{where}: element {kind} is not supported")
            try:  # before its name becomes a directory below
                check_subsim_name(name)
            except ValueError as exc:
                raise ScenarioError(f"{where}: {exc}") from None
            source = comp.get("source", "")
            if comp.get("type") not in FMU_TYPES or not source.lower().endswith(".fmu"):
                raise ScenarioError(f"{where}: only FMU components are supported (type "
                                    f"{comp.get('type')!r}, source {source!r})")
            member = str(PurePosixPath(source.removeprefix("file:")))
            try:
                data = zf.read(member)
            except KeyError:
                raise ScenarioError(f"{where}: its FMU {source!r} is not in the archive") from None
            fmu = target / name / PurePosixPath(member).name
            fmu.parent.mkdir(parents=True, exist_ok=True)
            fmu.write_bytes(data)
            model = _read_model(data)
            params: dict[str, Any] = {}
            for binding in _bindings(comp):
                for _, variable, value in binding_values(binding, zf, where, ssd_units,
                                                         lambda n, c=name, m=model: (c, m, n)):
                    _bind(params, variable, value)
            interface = _interface(comp, model, where, source)
            if interface is not None:  # before the companion's params, which override it
                params["interface"] = interface
            params["fmu"] = str(fmu)
            raw["subsims"][name] = {"model": MODEL, "params": params}
            ends[name] = _End(model, {c.get("name", ""): _connector_unit(c) for c in inner(comp, "Connectors")})
        for binding in _bindings(system):  # after the components': they win
            where = f"{path}: system {system_name!r}"
            for name, variable, value in binding_values(binding, zf, where, ssd_units,
                                                        partial(_in_system, ends, where)):
                _bind(raw["subsims"][name]["params"], variable, value)
        for conn in (c for c in inner(system, "Connections") if local(c.tag) == "Connection"):
            raw["couplings"].append(_coupling(conn, ends, ssd_units, f"{path}: connection", system_name))
    if not raw["subsims"]:
        raise ScenarioError(f"{path}: the system has no FMU components")
    raw = _with_companion(raw, path)
    start = raw.get("start", 0.0)
    if isinstance(start, (int, float)) and start != 0.0:  # the FMUs start where the run does (a bad one: parse says)
        for table in raw["subsims"].values():
            table["params"].setdefault("start_time", start)
    if "stop" not in raw:
        raise ScenarioError(f"{path}: no stop time: give DefaultExperiment stopTime in the SSD or stop = ... in "
                            f"{path.with_suffix('.toml').name} beside it")
    if "interval" not in raw.get("coupling", {}):  # SSP has no communication step; a default one would be a guess
        raise ScenarioError(f"{path}: no coupling interval: give [coupling] interval = ... (and samples) in "
                            f"{path.with_suffix('.toml').name} beside it")
    return raw


def _with_companion(raw: dict[str, Any], path: Path) -> dict[str, Any]:
    companion = path.with_suffix(".toml")
    if not companion.is_file():
        return raw
    try:
        extra = tomllib.loads(companion.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{companion}: not valid TOML: {exc}") from None
    unknown = sorted(set(extra) - COMPANION_KEYS)
    if unknown:
        raise ScenarioError(f"{companion}: unknown key(s) {unknown}; allowed: {sorted(COMPANION_KEYS)}")
    for name, table in extra.pop("subsims", {}).items():
        if name not in raw["subsims"]:
            raise ScenarioError(f"{companion}: [subsims.{name}] is not a component of {path.name}; components: "
                                f"{sorted(raw['subsims'])}")
        if not isinstance(table, dict) or set(table) - {"params"} or not isinstance(table.get("params", {}), dict):
            raise ScenarioError(f"{companion}: [subsims.{name}] may only hold a params table")
        raw["subsims"][name]["params"].update(table.get("params", {}))
    return {**raw, **extra}
