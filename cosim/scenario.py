"""Scenario files (TOML) parsed once into a checked, immutable :class:`Scenario`.

Loading checks structure, types and names; every error names the file and the offending key.
Signals and sizes are checked against the subsims' own port declarations when the run starts
(ports may depend on parameters): see :func:`cosim.runner.build_plan`, whose errors name the
coupling's key too. Every key a scenario may hold is in :data:`KEYS` (docs/scenarios.md is
tested against it).
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from importlib.metadata import entry_points
from pathlib import Path
from types import MappingProxyType
from typing import Any

from cosim.coupler.convergence import Tolerance
from cosim.coupler.couplings import Coupling
from cosim.coupler.interval_control import IntervalControl
from cosim.coupler.order import check_order
from cosim.coupler.relaxation import METHODS, Settings
from cosim.importing import add_search_path, load_model
from cosim.protocol.keys import check_name
from cosim.protocol.security import Security
from cosim.subsim import Subsim, closest


@dataclass(frozen=True)
class Key:
    """One scenario key: the table it sits in, its TOML type, default, unit and meaning."""

    type: str
    default: str
    unit: str
    meaning: str


# table -> key -> Key. "subsims.<name>", "coupling.<method>" and "tolerances.<signal>" stand for any name.
KEYS: dict[str, dict[str, Key]] = {
    "": {
        "name": Key("string", "file name without .toml", "", "scenario name; names the default result file"),
        "description": Key("string", '""', "", "one line shown by cosim describe"),
        "start": Key("number", "0.0", "s", "simulated start time; every subsim is configured at it"),
        "stop": Key("number", "required", "s", "simulated stop time; whole intervals run until one ends at or past it "
                    "(with interval = 'auto' the last one is cut to end at it)"),
    },
    "subsims.<name>": {
        "model": Key("string", "required unless external", "",
                     "'package.module:Class' of a cosim.Subsim; launched as its own process"),
        "external": Key("boolean", "false", "",
                        "true: not launched; cosim run prints the command to start it and waits for it"),
        "params": Key("table", "{}", "the parameter's",
                      "parameters of the model's initial_state; a model that declares its parameters refuses others"),
        "inputs": Key("table", "{}", "the port's",
                      "constant values of inputs no coupling feeds: port = number or [numbers], one per channel"),
        "guess": Key("table", "{}", "the port's",
                     "what a coupled input stands at where no value of it is known yet, instead of zeros: the first "
                     "interval's stage 0 (every interval's with first_guess = 'zero'); port = number or [numbers]"),
        "doc": Key("string", '""', "", "free text"),
        "fmu": Key("string", "none", "", "an FMU file instead of model (relative to the scenario file; needs the fmi "
                   "extra): stands for model = 'subsims.fmu:FmuSubsim' with params.fmu = the path (docs/fmi.md)"),
        "launcher": Key("list of strings", "none", "",
                        "run this subsim on another machine: cosim run starts it (and restarts it) with this command "
                        "followed by one shell line, e.g. ['ssh', 'lab-2']; needs --listen on an address that "
                        "machine reaches (docs/scenarios.md, Subsims on other machines)"),
        "workdir": Key("string", "none", "",
                       "with launcher: the directory there to run in (its models import from it)"),
        "python": Key("string", '"python3"', "", "with launcher: the Python there, with cosim installed"),
        "connect": Key("string", "the --listen endpoint", "",
                       "with launcher: the coordinator's endpoint as that machine reaches it"),
    },
    "couplings[]": {
        "to": Key("string", "required", "", "the input driven, 'subsim.port'"),
        "from": Key("string or list of strings", "required", "", "the output(s) read, 'subsim.port'"),
        "transform": Key("string", '"identity"', "",
                         "'identity', 'gain', 'linear' or 'package.module:function' (see Transforms)"),
        "params": Key("table", "{}", "", "keyword arguments of the transform"),
        "doc": Key("string", '""', "", "free text"),
    },
    "coupling": {
        "method": Key("string", '"centralized"', "", "default method: 'centralized' (RF-C) or 'distributed' (RF-D)"),
        "interval": Key("number or \"auto\"", "required", "s",
                        "convergence interval length H; 'auto': sized per interval by the interval_* keys "
                        "(cosim/coupler/interval_control.py)"),
        "interval_tol": Key("number", "1e-8", "1",
                            "interval = 'auto': largest estimated interpolation error of every coupled input "
                            "between its samples, relative to that channel's largest magnitude so far in the run "
                            "(never below res); "
                            "a larger estimate rolls the interval back and retries it shorter (an interval at "
                            "interval_min is accepted, its ratio in the diagnostics' error column)"),
        "interval_initial": Key("number", "0.1", "s", "interval = 'auto': length of the first interval"),
        "interval_min": Key("number", "interval_initial / 1024", "s",
                            "interval = 'auto': shortest interval; one that does not converge at it stops the run"),
        "interval_max": Key("number", "interval_initial * 1024", "s", "interval = 'auto': longest interval"),
        "interval_stages": Key("integer", "3 distributed, 4 centralized", "",
                               "interval = 'auto': stages per interval aimed at; the interval grows while "
                               "intervals converge in fewer, holds at this many, shrinks above (Jacobi needs "
                               "a stage more than Gauss-Seidel)"),
        "samples": Key("integer", "5", "", "samples per interval, both ends included (the paper's ndp)"),
        "first_guess": Key("string", '"extrapolate"', "", "stage-0 inputs: 'zero', 'hold' or 'extrapolate'"),
        "interp": Key("string", '"linear"', "", "input interpolation: 'linear', 'cubic' or 'lagrange' (for smooth "
                      "signals 'cubic' is far more accurate at the same cost: linear is the paper's)"),
        "tol": Key("number", "1e-10", "1", "relative convergence tolerance (of the newest stage's span)"),
        "res": Key("number", "1e-12", "signal unit", "absolute convergence tolerance"),
        "max_stages": Key("integer", "100", "", "stages before an interval counts as not converged (sooner when, "
                          "from the fifth stage on, its signals come back bit for bit to those of up to 4 stages "
                          "before: a cycle that would go round to the limit)"),
        "order": Key("list of strings", "derived", "", "distributed execution order; every subsim once"),
        "max_halvings": Key("integer", "0", "", "times a non-converging interval is retried shorter: on its "
                            "first half, then its first quarter, ...; not used with interval = 'auto', which "
                            "shortens intervals itself"),
        "speculate": Key("boolean", "false", "",
                         "distributed: from stage 1 on, run a group beside the one before it on that one's previous "
                         "outputs, kept when they come back bit for bit the same (fewer round trips, same results)"),
    },
    "coupling.<method>": {},  # the keys of [coupling] but method, for one method only
    "tolerances.<signal>": {
        "rel": Key("number", "0.0", "1", "relative tolerance of this signal (replaces tol)"),
        "abs": Key("number", "0.0", "signal unit", "absolute tolerance of this signal (replaces res)"),
    },
    "output": {
        "path": Key("string", '"results/<name>-<method>.csv"', "",
                    "result file, .csv or .npz; relative to the working directory"),
        "signals": Key("list of strings", "every output", "", "'subsim.port' outputs to write"),
    },
    "run": {
        "restarts": Key("integer", "2", "", "replacements of subsims that die or hang before the run fails (0: fail)"),
        "timeout": Key("number", "auto", "s", "wait for a reply before a subsim counts as hung; auto: the largest of "
                       "1.5 s (10 s when a subsim is external or has a launcher: network blips), 50 times the median "
                       "and 3 times the slowest recent request (30 s for the first few)"),
        "checkpoint_every": Key("integer", "200", "", "intervals between checkpoints of every subsim's state (for "
                                "replacements, and the resume points of `cosim run --resume`)"),
        "lease": Key("number", "10", "s", "Zenoh link lease of the subsims: how long a silent link lives (an external "
                                          "subsim's printed command carries it as --lease)"),
    },
    "security": {
        "tls_cert": Key("string", "none", "", "router certificate (PEM); with tls_key the router listens on tls/"),
        "tls_key": Key("string", "none", "", "private key of tls_cert (PEM)"),
        "tls_ca": Key("string", "none", "", "CA certificate launched subsims verify the router with (PEM)"),
        "mutual": Key("boolean", "false", "", "true: subsims must present certificates signed by tls_ca"),
        "auth_file": Key("string", "none", "", "'user:password' lines that may log in besides the run's own login"),
        "admin_space": Key("boolean", "false", "", "open Zenoh's admin space of the router"),
    },
    "unified": {
        "function": Key("string", "none", "", "'package.module:function' of the one-integrator reference (RK-U)"),
        "params": Key("table", "{}", "", "keyword arguments of that function"),
    },
}
KEYS["coupling.<method>"] = {k: v for k, v in KEYS["coupling"].items() if k != "method"}
INTERVAL_REQUIRED = ("is required: the convergence interval in s, short against the fastest coupled dynamics (a tenth "
                     "of the shortest period is a start; a run converges at any length, but the signals between "
                     "samples are only interpolated), or interval = \"auto\" to have each one sized to interval_tol")
AUTO_STAGES = {"distributed": 3, "centralized": 4}  # interval_stages' default: a Jacobi stage passes on one coupling
# per stage, so it converges a stage later than Gauss-Seidel (3 stages where Gauss-Seidel takes 2)
AUTO_KEYS = ("interval_tol", "interval_initial", "interval_min", "interval_max", "interval_stages")
TABLES = {"coupling", "subsims", "couplings", "tolerances", "output", "unified", "run", "security"}


class ScenarioError(ValueError):
    pass


@dataclass(frozen=True)
class SubsimSpec:
    name: str
    model: str | None  # "package.module:Class"; None for an external subsim
    external: bool
    params: Mapping[str, Any]
    inputs: Mapping[str, tuple[float, ...]] = field(default_factory=dict)  # held constant: port -> values
    guess: Mapping[str, tuple[float, ...]] = field(default_factory=dict)  # coupled: port -> values before any known
    launcher: tuple[str, ...] = ()  # started elsewhere by this command and one shell line (empty: here)
    workdir: str | None = None  # with launcher: where it runs there
    python: str = "python3"  # with launcher: the Python there
    connect: str | None = None  # with launcher: the coordinator's endpoint as seen from there (None: the listen one)
    search_path: tuple[str, ...] = ()  # the scenario's directory and the working directory: where its modules are

    def model_class(self) -> type[Subsim]:
        return load_model(self.model or "", self.search_path)


@dataclass(frozen=True)
class UnifiedSpec:
    function: str  # "package.module:function"
    params: Mapping[str, Any]


@dataclass(frozen=True)
class RunSpec:
    """Fault handling of a run ([run])."""

    restarts: int = 2
    timeout: float | None = None  # None: derived from measured request times
    checkpoint_every: int = 200
    lease: float = 10.0


@dataclass(frozen=True)
class Scenario:
    path: Path
    name: str
    description: str
    start: float
    stop: float
    subsims: Mapping[str, SubsimSpec]
    couplings: tuple[Coupling, ...]
    settings: Mapping[str, Settings]  # per method
    default_method: str
    output_path: Path | None
    output_signals: tuple[str, ...] | None
    unified: UnifiedSpec | None = None
    run: RunSpec = RunSpec()
    security: Security | None = None  # [security]; paths relative to the scenario file
    raw: Mapping[str, Any] = field(default_factory=dict)  # the file's tables, for variants: parse({**raw, ...})
    search_path: tuple[str, ...] = ()  # its directory and the working directory (cosim.importing)

    def settings_for(self, method: str | None = None) -> Settings:
        method = method or self.default_method
        if method not in self.settings:
            raise ScenarioError(f"{self.path}: method {method!r} unknown; use one of {', '.join(METHODS)}, or unified "
                                "(the scenario's [unified] reference)")
        return self.settings[method]


def check_subsim_name(name: str) -> str:
    """A scenario's subsim name: a bus name (``check_name``) without '.', which separates a subsim from its
    port in signal names (``subsim.port``). ValueError in one line."""
    try:
        check_name(name, "subsim name")
    except ValueError:  # (the bus's own words allowed '.': a docs probe)
        raise ValueError(f"subsim name {name!r} must be 1-64 characters of letters, digits, '_' or '-'") from None
    if "." in name:
        raise ValueError(f"subsim name {name!r} has a '.', which separates a subsim from its port in signal "
                         f"names ('{name}.<port>' would read as subsim {name.partition('.')[0]!r}); "
                         f"use '_' or '-' instead")
    return name


def _plugins(group: str) -> dict[str, Any]:
    """Entry points of ``group`` by name (other packages extend the loader without the loader importing them)."""
    return {ep.name: ep for ep in entry_points(group=group)}


def load(path: str | Path) -> Scenario:
    """A scenario file: TOML, or a format a package registers under the ``cosim.formats`` entry points (.ssp).
    Its directory and the working directory go on the import path first (see
    :func:`cosim.importing.add_search_path`): a scenario may name modules beside it."""
    path = Path(path)
    add_search_path(path.resolve().parent, Path.cwd())
    formats = _plugins("cosim.formats")
    suffix = path.suffix.lower().lstrip(".")
    if suffix != "toml" and suffix in formats:
        return parse(formats[suffix].load()(path), path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ScenarioError(f"scenario file {path} not found") from None
    except IsADirectoryError:
        raise ScenarioError(f"{path} is a directory: give a scenario file (.toml) in it") from None
    except UnicodeDecodeError:
        if suffix in _plugins("cosim.subsim_shorthands"):  # e.g. an .fmu given to cosim run (an FMI probe)
            raise ScenarioError(f"{path}: a .{suffix} file, not a scenario: couple it in a scenario (TOML), in a "
                                f"[subsims.<name>] table with {suffix} = {path.name!r}") from None
        raise ScenarioError(f"{path}: not a text file, so not a scenario (TOML)") from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    return parse(raw, path)


def parse(raw: Mapping[str, Any], path: Path) -> Scenario:
    """Check every table of ``raw`` (a parsed scenario file) and build the scenario."""
    p = _Parser(path)
    p.known(raw, set(KEYS[""]) | TABLES, "top level")
    start = p.start = p.number(raw, "start", 0.0)
    stop = p.number(raw, "stop")
    if stop <= start:
        raise p.fail("stop", f"must be after start ({start}), got {stop}")
    subsims = p.subsims(raw.get("subsims"))
    couplings = tuple(p.coupling(i, c, subsims) for i, c in enumerate(p.list_of_tables(raw, "couplings")))
    settings, default_method = p.settings(p.table(raw, "coupling"), p.tolerances(p.table(raw, "tolerances")), subsims)
    out_path, signals = p.output(p.table(raw, "output"))
    return Scenario(path, p.string(raw, "name", path.stem), p.string(raw, "description", ""), start, stop,
                    MappingProxyType(subsims), couplings, MappingProxyType(settings), default_method, out_path,
                    signals, p.unified(p.table(raw, "unified")), p.run(p.table(raw, "run")),
                    p.security(p.table(raw, "security")),
                    MappingProxyType(dict(raw)), p.search_path)


def with_method(s: Scenario, method: str) -> Scenario:
    return replace(s, default_method=method)


class _Parser:
    """The checks of one file; each method checks one table and names its key in every error."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.search_path = (str(path.resolve().parent), os.path.abspath(Path.cwd()))  # as load() adds them
        self.start = 0.0
        self.shorthands = _plugins("cosim.subsim_shorthands")

    def fail(self, key: str, msg: str) -> ScenarioError:
        return ScenarioError(f"{self.path}: [{key}] {msg}")

    def known(self, table: Mapping, allowed: set[str], key: str) -> None:
        extra = sorted(set(table) - allowed)
        if extra:
            close = {k: m for k in extra if (m := closest(str(k), sorted(allowed)))}
            if len(extra) == 1 and close:
                hint = f" (did you mean {close[extra[0]]!r}?)"
            else:
                hint = f" (did you mean {', '.join(f'{m!r} for {k!r}' for k, m in close.items())}?)" if close else ""
            raise self.fail(key, f"unknown key(s) {extra}{hint}; allowed: {sorted(allowed)}")

    def number(self, table: Mapping, key: str, default: float | None = None, where: str = "") -> float:
        v = table.get(key, default)
        if v is None:
            raise self.fail(f"{where}.{key}" if where else key, f"is required: {key} = <a number>")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):  # (TOML has inf, nan)
            raise self.fail(f"{where}.{key}" if where else key, f"must be a finite number, got {v!r}")
        return float(v)

    def string(self, table: Mapping, key: str, default: str, where: str = "") -> str:
        v = table.get(key, default)
        if not isinstance(v, str):
            raise self.fail(f"{where}.{key}" if where else key, f"must be a string, got {v!r}")
        return v

    def table(self, raw: Mapping, key: str, where: str | None = None) -> Mapping[str, Any]:
        value = raw.get(key, {})
        if not isinstance(value, dict):
            raise self.fail(where or key, "must be a table")
        return value

    def list_of_tables(self, raw: Mapping, key: str) -> list[Mapping[str, Any]]:
        value = raw.get(key, [])
        if not isinstance(value, list):
            raise self.fail(key, f"must be a list of tables ([[{key}]])")
        for i, item in enumerate(value):
            if not isinstance(item, dict):
                raise self.fail(f"{key}[{i}]", f"must be a table ([[{key}]])")
        return value

    def subsims(self, table: Any) -> dict[str, SubsimSpec]:
        if not isinstance(table, dict) or not table:
            raise self.fail("subsims", "at least one [subsims.<name>] table is required")
        return {name: self.subsim(name, spec) for name, spec in table.items()}

    def subsim(self, name: str, spec: Any) -> SubsimSpec:
        key = f"subsims.{name}"
        try:
            check_subsim_name(name)
        except ValueError as exc:
            raise self.fail(key, str(exc)) from None
        if not isinstance(spec, dict):
            raise self.fail(key, "must be a table")
        for short, expander in self.shorthands.items():  # e.g. fmu = "path.fmu" (subsims/fmu)
            if short in spec:
                spec = expander.load()(spec, self.path, self.start, key)
        self.known(spec, set(KEYS["subsims.<name>"]), key)
        self.string(spec, "doc", "", key)
        external = spec.get("external", False)
        if not isinstance(external, bool):
            raise self.fail(f"{key}.external", "must be true or false")
        model = spec.get("model")
        if model is None and not external:
            raise self.fail(key, "needs model = 'package.module:Class' (or external = true)")
        elsewhere = self.launcher(spec, key, external)
        if model is not None and not elsewhere:  # one started elsewhere imports it there, not here
            try:
                load_model(model, self.search_path)
            except ValueError as exc:
                raise self.fail(f"{key}.model", str(exc)) from None
        params = self.table(spec, "params", f"{key}.params")
        inputs, guess = self.port_values(spec, "inputs", key), self.port_values(spec, "guess", key)
        return SubsimSpec(name, model, external, MappingProxyType(dict(params)), MappingProxyType(inputs),
                          MappingProxyType(guess), **elsewhere, search_path=self.search_path)

    def port_values(self, spec: Mapping[str, Any], table: str, key: str) -> dict[str, tuple[float, ...]]:
        """A subsim's table of values by input port (``inputs``, ``guess``): port = number or [numbers]."""
        found = {}
        for port, value in self.table(spec, table, f"{key}.{table}").items():
            values = value if isinstance(value, list) else [value]
            if not values or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in values):
                raise self.fail(f"{key}.{table}.{port}", f"must be a number or a list of numbers, got {value!r}")
            found[port] = tuple(float(v) for v in values)
        return found

    def launcher(self, spec: Mapping[str, Any], key: str, external: bool) -> dict[str, Any]:
        """The launcher keys of a subsim started on another machine, as SubsimSpec fields ({} if none)."""
        given = [k for k in ("launcher", "workdir", "python", "connect") if k in spec]
        if not given:
            return {}
        if "launcher" not in spec:
            raise self.fail(f"{key}.{given[0]}", "applies to a subsim started elsewhere: add launcher = [...] "
                            "(e.g. ['ssh', 'host'])")
        launcher = spec["launcher"]
        if not isinstance(launcher, list) or not launcher or not all(isinstance(w, str) and w for w in launcher):
            raise self.fail(f"{key}.launcher", f"must be a non-empty list of strings, e.g. ['ssh', 'lab-2'], got "
                            f"{launcher!r}")
        if external:
            raise self.fail(key, "give launcher (cosim starts it elsewhere) or external = true (you start it), "
                            "not both")
        fields: dict[str, Any] = {"launcher": tuple(launcher)}
        for name in ("workdir", "python", "connect"):
            if name in spec:
                value = spec[name]
                if not isinstance(value, str) or not value:
                    raise self.fail(f"{key}.{name}", f"must be a non-empty string, got {value!r}")
                proto, slash, address = value.partition("/")
                if name == "connect" and not (slash and proto.isalnum() and address.rpartition(":")[2].isdigit()):
                    raise self.fail(f"{key}.connect", f"must be an endpoint such as 'tcp/192.168.1.10:7447', got "
                                    f"{value!r}")
                fields[name] = value
        return fields

    def coupling(self, i: int, c: Mapping[str, Any], subsims: Mapping[str, SubsimSpec]) -> Coupling:
        key = f"couplings[{i}]"
        self.known(c, set(KEYS["couplings[]"]), key)
        for required in ("to", "from"):
            if required not in c:
                raise self.fail(key, f"missing {required!r}")
        self.string(c, "to", "", key)
        self.string(c, "doc", "", key)
        sources = c["from"] if isinstance(c["from"], list) else [c["from"]]
        if not sources or not all(isinstance(src, str) for src in sources):
            raise self.fail(f"{key}.from", f"must be a 'subsim.port' string or a list of them, got {c['from']!r}")
        try:
            coupling = Coupling.make(c["to"], c["from"], c.get("transform", "identity"), c.get("params", {}),
                                     self.search_path)
        except (ValueError, TypeError) as exc:
            raise self.fail(key, str(exc)) from None
        for ref in (coupling.target, *coupling.sources):
            if ref.subsim not in subsims:
                raise self.fail(key, f"unknown subsim {ref.subsim!r} in {str(ref)!r}; subsims: {sorted(subsims)}")
        return coupling

    def tolerances(self, table: Mapping[str, Any]) -> dict[str, Tolerance]:
        out = {}
        for signal, t in table.items():
            key = f"tolerances.{signal!r}"
            if not isinstance(t, dict) or not t:
                raise self.fail(key, "must be a table with rel and/or abs")
            self.known(t, set(KEYS["tolerances.<signal>"]), key)
            try:
                out[signal] = Tolerance(t.get("rel", 0.0), t.get("abs", 0.0))
            except ValueError as exc:
                raise self.fail(key, str(exc)) from None
        return out

    def settings(
        self, table: Mapping[str, Any], tolerances: Mapping[str, Tolerance], subsims: Mapping[str, SubsimSpec]
    ) -> tuple[dict[str, Settings], str]:
        """Per method: [coupling] overridden by [coupling.<method>]; and the default method."""
        base = {k: v for k, v in table.items() if k not in METHODS}
        self.known(base, set(KEYS["coupling"]), "coupling")
        default_method = base.get("method", "centralized")
        if default_method not in METHODS:
            raise self.fail("coupling.method", f"must be one of {METHODS}, got {default_method!r}")
        settings = {}
        for method in METHODS:
            over = self.table(table, method, f"coupling.{method}")
            self.known(over, set(KEYS["coupling.<method>"]), f"coupling.{method}")
            if "interval" not in base and "interval" not in over:  # no default fits every model: a wrong one is
                raise self.fail("coupling.interval", INTERVAL_REQUIRED)  # silently inaccurate, not an error
        self.method_settings(base, "centralized", tolerances, subsims, "coupling")  # valid on its own
        for method in METHODS:
            over = self.table(table, method, f"coupling.{method}")
            settings[method] = self.method_settings({**base, **over}, method, tolerances, subsims, f"coupling.{method}")
        return settings, default_method

    def method_settings(
        self, table: Mapping[str, Any], method: str, tolerances: Mapping[str, Tolerance],
        subsims: Mapping[str, SubsimSpec], where: str,
    ) -> Settings:
        merged = dict(table)
        try:
            tol = Tolerance(merged.pop("tol", 1e-10), merged.pop("res", 1e-12))
            merged.update(self.auto_interval(merged, where, method))
            order = merged.get("order")
            if order is not None:
                merged["order"] = check_order(order, list(subsims))
            return Settings(tol=tol, tolerances=MappingProxyType(dict(tolerances)), **{**merged, "method": method})
        except ScenarioError:
            raise
        except (ValueError, TypeError) as exc:
            raise self.fail(where, str(exc)) from None

    def auto_interval(self, merged: dict[str, Any], where: str, method: str) -> dict[str, Any]:
        """Pops the interval_* keys from ``merged``; with interval = "auto" returns interval and auto."""
        keys = {k: merged.pop(k) for k in AUTO_KEYS if k in merged}
        if merged.get("interval") != "auto":
            if keys:
                raise self.fail(where, f"{sorted(keys)} need interval = \"auto\"")
            return {}
        for k, v in keys.items():
            if k != "interval_stages" and (isinstance(v, bool) or not isinstance(v, (int, float))):
                raise self.fail(f"{where}.{k}", f"must be a number, got {v!r}")
        initial = float(keys.get("interval_initial", 0.1))
        control = IntervalControl(tol=float(keys.get("interval_tol", 1e-8)), initial=initial,
                                  minimum=float(keys.get("interval_min", initial / 1024)),
                                  maximum=float(keys.get("interval_max", initial * 1024)),
                                  stages=keys.get("interval_stages", AUTO_STAGES[method]))
        return {"interval": control.initial, "auto": control}

    def output(self, table: Mapping[str, Any]) -> tuple[Path | None, tuple[str, ...] | None]:
        self.known(table, set(KEYS["output"]), "output")
        out_path = Path(self.string(table, "path", "", "output")) if "path" in table else None
        if out_path is not None and not out_path.is_absolute():
            out_path = Path.cwd() / out_path
        signals = table.get("signals")
        if signals is not None and (not isinstance(signals, list) or not all(isinstance(s, str) for s in signals)):
            raise self.fail("output.signals", "must be a list of 'subsim.port' strings")
        return out_path, tuple(signals) if signals is not None else None

    def run(self, table: Mapping[str, Any]) -> RunSpec:
        self.known(table, set(KEYS["run"]), "run")
        spec = RunSpec()
        for key in ("restarts", "checkpoint_every"):
            v = table.get(key, getattr(spec, key))
            if isinstance(v, bool) or not isinstance(v, int) or v < (0 if key == "restarts" else 1):
                raise self.fail(f"run.{key}", f"must be an integer >= {0 if key == 'restarts' else 1}, got {v!r}")
        timeout = table.get("timeout", "auto")
        if timeout != "auto":
            timeout = self.number(table, "timeout", where="run")
            if not 0 < timeout < float("inf"):
                raise self.fail("run.timeout", f"must be 'auto' or a positive number of seconds, got {timeout!r}")
        lease = self.number(table, "lease", spec.lease, where="run")
        if not 0.5 <= lease <= 3600:
            raise self.fail("run.lease", f"must be between 0.5 and 3600 seconds, got {lease!r}")
        return RunSpec(table.get("restarts", spec.restarts), None if timeout == "auto" else timeout,
                       table.get("checkpoint_every", spec.checkpoint_every), lease)

    def unified(self, table: Mapping[str, Any]) -> UnifiedSpec | None:
        self.known(table, set(KEYS["unified"]), "unified")
        function = table.get("function")
        if function is None:
            return None
        if not isinstance(function, str) or ":" not in function:
            raise self.fail("unified.function", f"must be 'package.module:function', got {function!r}")
        params = self.table(table, "params", "unified.params")
        return UnifiedSpec(function, MappingProxyType(dict(params)))

    def security(self, table: Mapping[str, Any]) -> Security | None:
        self.known(table, set(KEYS["security"]), "security")
        if not table:
            return None
        files = {}
        for key in ("tls_cert", "tls_key", "tls_ca", "auth_file"):
            if key in table:
                if not isinstance(table[key], str):
                    raise self.fail(f"security.{key}", "must be a file path string")
                files[key] = (self.path.parent / table[key]).resolve()
        flags = {}
        for key in ("mutual", "admin_space"):
            if not isinstance(table.get(key, False), bool):
                raise self.fail(f"security.{key}", "must be true or false")
            flags[key] = table.get(key, False)
        try:
            return Security(**files, **flags).check()
        except ValueError as exc:
            raise self.fail("security", str(exc)) from None
