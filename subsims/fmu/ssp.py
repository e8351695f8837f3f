"""SSP import and the ``fmu = "path.fmu"`` scenario shorthand: both produce the raw scenario dict a
scenario TOML parses to, so ``cosim.scenario.parse`` checks them like any scenario.

``read_ssp("system.ssp")`` reads ``SystemStructure.ssd`` from the SSP archive (System Structure and
Parameterization 1.0/2.0): every FMU component becomes a subsim (its FMU extracted to a directory that
lives as long as this process), every connection a coupling (a ``LinearTransformation`` becomes the
``linear`` transform), parameter bindings (inline or ``.ssv`` files in the archive) become params, and
``DefaultExperiment`` gives start and stop. A companion ``system.toml`` beside ``system.ssp`` may add or
override the top-level scenario tables (``stop``, ``[coupling]`` with method, interval, samples, tol ...,
``[tolerances]``, ``[output]``) and per-subsim params (``[subsims.<name>.params]``).
Not supported (refused with the element named): nested systems, system-level connectors, signal
dictionaries, components that are not FMUs, transformations other than linear ones.
"""

from __future__ import annotations

import tempfile
import tomllib
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Mapping
from pathlib import Path, PurePosixPath
from typing import Any

from cosim.scenario import ScenarioError, check_subsim_name
from subsims.fmu.scratch import process_dir

MODEL = "subsims.fmu:FmuSubsim"
FMU_TYPES = {"application/x-fmu-sharedlibrary", None}
LAYOUT_ONLY = {"ConnectionGeometry", "Annotations"}  # children of a Connection that carry no coupling
COMPANION_KEYS = {"name", "description", "start", "stop", "coupling", "tolerances", "output", "subsims"}


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
    if "launcher" in table:  # started on another machine: a path there, relative to its workdir
        params = {**params, "fmu": fmu}
    else:
        resolved = (scenario.parent / fmu).resolve()
        if not table.get("external", False) and not resolved.is_file():  # launched here: a typo, found at load
            raise ScenarioError(f"{scenario}: [{key}.fmu] no such file: {resolved}")
        params = {**params, "fmu": str(resolved)}
    if start != 0.0:
        params.setdefault("start_time", start)
    return {**table, "model": MODEL, "params": params}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _children(elem: ET.Element, name: str) -> list[ET.Element]:
    return [c for c in elem if _local(c.tag) == name]


def _child(elem: ET.Element, name: str) -> ET.Element | None:
    found = _children(elem, name)
    return found[0] if found else None


def _extract_dir() -> Path:
    return Path(tempfile.mkdtemp(dir=process_dir("cosim-ssp-")))


def _value(param: ET.Element, where: str) -> Any:
    for typed in param:
        kind, raw = _local(typed.tag), typed.get("value")
        if raw is None:
            continue
        try:
            if kind in {"Real", "Float64", "Float32"}:
                return float(raw)
            if kind in {"Integer", "Enumeration"} or kind.startswith(("Int", "UInt")):
                return int(raw)
            if kind == "Boolean":
                if raw not in {"true", "false", "1", "0"}:
                    raise ValueError(raw)
                return raw in {"true", "1"}
            if kind == "String":
                return raw
        except ValueError:
            raise ScenarioError(f"{where}: parameter {param.get('name')!r}: bad {kind} value {raw!r}") from None
    raise ScenarioError(f"{where}: parameter {param.get('name')!r} has no Real/Integer/Boolean/String value")


def _parameters(binding: ET.Element, zf: zipfile.ZipFile, where: str) -> dict[str, Any]:
    source = binding.get("source")
    if source is not None:
        if source.startswith("#"):
            raise ScenarioError(f"{where}: parameter binding references ({source!r}) are not supported")
        try:
            root = ET.fromstring(zf.read(str(PurePosixPath(source))))
        except KeyError:
            raise ScenarioError(f"{where}: parameter file {source!r} is not in the archive") from None
        except ET.ParseError as exc:
            raise ScenarioError(f"{where}: parameter file {source!r} is not valid XML ({exc})") from None
    else:
        values = _child(binding, "ParameterValues")
        root = _child(values, "ParameterSet") if values is not None else None
        if root is None:
            return {}
    prefix = binding.get("prefix", "")
    out = {}
    for params in _children(root, "Parameters"):
        for param in _children(params, "Parameter"):
            name = param.get("name", "")
            if prefix and name.startswith(prefix):
                name = name[len(prefix):]
            out[name] = _value(param, where)
    return out


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
        system = _child(root, "System")
        if system is None:
            raise ScenarioError(f"{path}: SystemStructure.ssd has no System")
        raw: dict[str, Any] = {"name": root.get("name") or path.stem, "subsims": {}, "couplings": []}
        experiment = _child(root, "DefaultExperiment")
        if experiment is not None:
            for attr, key in (("startTime", "start"), ("stopTime", "stop")):
                if experiment.get(attr) is not None:
                    try:
                        raw[key] = float(experiment.get(attr))
                    except ValueError:
                        raise ScenarioError(f"{path}: DefaultExperiment {attr} is not a number") from None
        target = _extract_dir()
        elements = _child(system, "Elements")
        for comp in list(elements) if elements is not None else []:
            kind = _local(comp.tag)
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
            params: dict[str, Any] = {}
            bindings = _child(comp, "ParameterBindings")
            for binding in _children(bindings, "ParameterBinding") if bindings is not None else []:
                params.update(_parameters(binding, zf, where))
            params["fmu"] = str(fmu)
            raw["subsims"][name] = {"model": MODEL, "params": params}
        connections = _child(system, "Connections")
        for conn in _children(connections, "Connection") if connections is not None else []:
            ends = [conn.get(a) for a in ("startElement", "startConnector", "endElement", "endConnector")]
            system_name = system.get("name") or "(unnamed)"  # the end a system-level connector belongs to
            text = f"{ends[0] or system_name}.{ends[1]} -> {ends[2] or system_name}.{ends[3]}"
            if not ends[0] or not ends[2]:
                raise ScenarioError(f"{path}: connection {text}: system-level connectors are not supported")
            coupling: dict[str, Any] = {"to": f"{ends[2]}.{ends[3]}", "from": f"{ends[0]}.{ends[1]}"}
            for transform in conn:
                if _local(transform.tag) in LAYOUT_ONLY:  # where an editor drew the line: nothing to couple
                    continue
                if _local(transform.tag) != "LinearTransformation":
                    raise ScenarioError(f"{path}: connection {text}: {_local(transform.tag)} is not supported")
                try:
                    factor, offset = float(transform.get("factor", 1.0)), float(transform.get("offset", 0.0))
                except ValueError:
                    raise ScenarioError(f"{path}: connection {text}: bad LinearTransformation") from None
                coupling.update(transform="linear", params={"gains": [factor], "offset": offset})
            raw["couplings"].append(coupling)
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
