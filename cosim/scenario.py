"""Scenario files (TOML): subsims, couplings, coupling settings, stop time and outputs.

Loading checks structure, types and names; every error names the file and the offending key.
Signals and sizes are checked against the subsims' own port declarations when the run starts
(ports may depend on parameters), and those errors name the coupling's key too.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.relaxation import METHODS, Settings
from cosim.importing import import_object
from cosim.protocol.bus import check_name
from cosim.subsim import Subsim

SETTING_KEYS = {"method", "interval", "samples", "first_guess", "interp", "tol", "res", "max_stages", "order",
                "max_halvings"}
TOP_KEYS = {"name", "description", "start", "stop", "coupling", "subsims", "couplings", "tolerances", "output",
            "unified"}
SUBSIM_KEYS = {"model", "external", "params", "doc"}
COUPLING_KEYS = {"to", "from", "transform", "params", "doc"}


class ScenarioError(ValueError):
    pass


@dataclass(frozen=True)
class SubsimSpec:
    name: str
    model: str | None  # "package.module:Class"; None for an external subsim
    external: bool
    params: dict[str, Any]

    def model_class(self) -> type[Subsim]:
        return load_model(self.model or "")


@dataclass(frozen=True)
class Scenario:
    path: Path
    name: str
    description: str
    start: float
    stop: float
    subsims: dict[str, SubsimSpec]
    couplings: list[Coupling]
    settings: dict[str, Settings]  # per method
    default_method: str
    output_path: Path | None
    output_signals: list[str] | None
    unified: str | None = None
    raw: dict = field(default_factory=dict, repr=False)

    def settings_for(self, method: str | None = None) -> Settings:
        method = method or self.default_method
        if method not in self.settings:
            raise ScenarioError(f"{self.path}: method {method!r} unknown; use one of {', '.join(METHODS)}")
        return self.settings[method]


def load_model(path: str) -> type[Subsim]:
    cls = import_object(path, "model")
    if not (isinstance(cls, type) and issubclass(cls, Subsim)):
        raise ValueError(f"model {path!r} is not a cosim.Subsim subclass")
    return cls


def load(path: str | Path) -> Scenario:
    path = Path(path)
    if path.suffix.lower() == ".ssp":  # SSP import: subsims/fmu/ssp.py (needs the fmi extra)
        from subsims.fmu.ssp import read_ssp
        return parse(read_ssp(path), path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ScenarioError(f"scenario file {path} not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    return parse(raw, path)


def parse(raw: Mapping[str, Any], path: Path) -> Scenario:
    def fail(key: str, msg: str) -> ScenarioError:
        return ScenarioError(f"{path}: [{key}] {msg}")

    def unknown(table: Mapping, allowed: set[str], key: str) -> None:
        extra = sorted(set(table) - allowed)
        if extra:
            raise fail(key, f"unknown key(s) {extra}; allowed: {sorted(allowed)}")

    def number(table: Mapping, key: str, where: str, default: float | None = None) -> float:
        v = table.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise fail(f"{where}.{key}" if where else key, f"must be a number, got {v!r}")
        return float(v)

    unknown(raw, TOP_KEYS, "top level")
    start = number(raw, "start", "", 0.0)
    stop = number(raw, "stop", "")
    if stop <= start:
        raise fail("stop", f"must be after start ({start}), got {stop}")

    subsims: dict[str, SubsimSpec] = {}
    table = raw.get("subsims")
    if not isinstance(table, dict) or not table:
        raise fail("subsims", "at least one [subsims.<name>] table is required")
    for name, spec in table.items():
        key = f"subsims.{name}"
        try:
            check_name(name, "subsim name")
        except ValueError as exc:
            raise fail(key, str(exc)) from None
        if not isinstance(spec, dict):
            raise fail(key, "must be a table")
        if "fmu" in spec:  # shorthand: fmu = "path.fmu" (subsims/fmu/ssp.py)
            from subsims.fmu.ssp import expand_fmu
            spec = expand_fmu(spec, path, start, key)
        unknown(spec, SUBSIM_KEYS, key)
        external = spec.get("external", False)
        if not isinstance(external, bool):
            raise fail(f"{key}.external", "must be true or false")
        model = spec.get("model")
        if model is None and not external:
            raise fail(key, "needs model = 'package.module:Class' (or external = true)")
        if model is not None:
            try:
                load_model(model)
            except ValueError as exc:
                raise fail(f"{key}.model", str(exc)) from None
        params = spec.get("params", {})
        if not isinstance(params, dict):
            raise fail(f"{key}.params", "must be a table")
        subsims[name] = SubsimSpec(name, model, external, params)

    couplings = []
    for i, c in enumerate(raw.get("couplings", [])):
        key = f"couplings[{i}]"
        if not isinstance(c, dict):
            raise fail(key, "must be a table ([[couplings]])")
        unknown(c, COUPLING_KEYS, key)
        for req in ("to", "from"):
            if req not in c:
                raise fail(key, f"missing {req!r}")
        try:
            coupling = Coupling.make(c["to"], c["from"], c.get("transform", "identity"), c.get("params", {}))
        except (ValueError, TypeError) as exc:
            raise fail(key, str(exc)) from None
        for ref in (coupling.target, *coupling.sources):
            if ref.subsim not in subsims:
                raise fail(key, f"unknown subsim {ref.subsim!r} in {str(ref)!r}; subsims: {sorted(subsims)}")
        couplings.append(coupling)

    tolerances = {}
    for sig, t in raw.get("tolerances", {}).items():
        key = f"tolerances.{sig!r}"
        if not isinstance(t, dict) or not set(t) <= {"rel", "abs"} or not t:
            raise fail(key, "must be a table with rel and/or abs")
        try:
            tolerances[sig] = Tolerance(t.get("rel", 0.0), t.get("abs", 0.0))
        except ValueError as exc:
            raise fail(key, str(exc)) from None

    coupling_table = raw.get("coupling", {})
    if not isinstance(coupling_table, dict):
        raise fail("coupling", "must be a table")
    base = {k: v for k, v in coupling_table.items() if k not in METHODS}
    unknown(base, SETTING_KEYS, "coupling")
    def build(table: Mapping[str, Any], method: str, where: str) -> Settings:
        merged = dict(table)
        try:
            tol = Tolerance(merged.pop("tol", 1e-10), merged.pop("res", 1e-12))
            order = merged.get("order")
            if order is not None and sorted(order) != sorted(subsims):
                raise ValueError(f"order {order} must list every subsim once: {sorted(subsims)}")
            return Settings(tol=tol, tolerances=tolerances, **{**merged, "method": method})
        except (ValueError, TypeError) as exc:
            raise fail(where, str(exc)) from None

    build(base, "centralized", "coupling")  # the shared table must be valid on its own
    settings = {}
    for method in METHODS:
        over = coupling_table.get(method, {})
        if not isinstance(over, dict):
            raise fail(f"coupling.{method}", "must be a table")
        unknown(over, SETTING_KEYS - {"method"}, f"coupling.{method}")
        settings[method] = build({**base, **over}, method, f"coupling.{method}")
    default_method = base.get("method", "centralized")
    if default_method not in METHODS:
        raise fail("coupling.method", f"must be one of {METHODS}, got {default_method!r}")

    output = raw.get("output", {})
    unknown(output, {"path", "signals"}, "output")
    out_path = Path(output["path"]) if "path" in output else None
    if out_path is not None and not out_path.is_absolute():
        out_path = Path.cwd() / out_path
    signals = output.get("signals")
    if signals is not None and (not isinstance(signals, list) or not all(isinstance(s, str) for s in signals)):
        raise fail("output.signals", "must be a list of 'subsim.port' strings")

    unified_table = raw.get("unified", {})
    if not isinstance(unified_table, dict):
        raise fail("unified", "must be a table")
    unknown(unified_table, {"function", "params"}, "unified")
    unified = unified_table.get("function")
    if unified is not None and (not isinstance(unified, str) or ":" not in unified):
        raise fail("unified.function", f"must be 'package.module:function', got {unified!r}")
    return Scenario(path, str(raw.get("name", path.stem)), str(raw.get("description", "")), start, stop, subsims,
                    couplings, settings, default_method, out_path, signals, unified, dict(raw))


def with_method(s: Scenario, method: str) -> Scenario:
    return replace(s, default_method=method)
