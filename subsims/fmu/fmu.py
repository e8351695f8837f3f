"""Reading an FMU and driving one instance of it through FMPy: the FMI side of the FMU subsim.

Everything here is FMI: the model description (:func:`read_fmu`), the settable variables, and
:class:`Instance`, one instantiated FMU with the few calls the subsim needs, the same for FMI 2.0 and
3.0, co-simulation (CS) and model exchange (ME). Every failure is an :class:`FmuError` (a bad file or
a bad value, before anything runs) or an :class:`FmiCallError` (a call the FMU refused while running),
with a one-line message.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from subsims.fmu.scratch import process_dir

try:
    import fmpy
    import fmpy.fmi2
    import fmpy.fmi3
    from fmpy.model_description import read_model_description
except ImportError:  # pragma: no cover - the fmi extra is not installed
    fmpy = None

INTERFACES = {"cs": "coSimulation", "me": "modelExchange"}
REAL_TYPES = {"Real", "Float64", "Float32"}
INT_TYPES = {"Integer", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64"}
FLOAT32_MAX = 3.4028234663852886e38
DISCARD = 2  # fmi2Discard, fmi3Discard
LOG_SHOWN = 20  # distinct warnings of one FMU instance printed; the rest are counted, not shown


def _int_range(fmi_type: str, major: int) -> tuple[int, int]:
    """The values an FMI integer type holds (FMI 2's Integer and Enumeration are C ints; FMI 3's are sized)."""
    if fmi_type in {"Integer"} or (fmi_type == "Enumeration" and major == 2):
        return -2**31, 2**31 - 1
    if fmi_type == "Enumeration":
        return -2**63, 2**63 - 1
    bits = int(fmi_type.removeprefix("U").removeprefix("Int"))
    return (0, 2**bits - 1) if fmi_type.startswith("U") else (-2**(bits - 1), 2**(bits - 1) - 1)


class FmuError(ValueError):
    """The FMU file, its description, or a value given for it is unusable; one line, naming the file."""


class FmiCallError(RuntimeError):
    """An FMI call failed while the FMU ran (the FMU's own last log message is appended when it gave one).
    ``discard``: it returned Discard (a step the FMU would take shorter)."""

    def __init__(self, message: str, discard: bool = False) -> None:
        super().__init__(message)
        self.discard = discard


def require_fmpy() -> None:
    if fmpy is None:
        raise FmuError("FMU support needs FMPy: pip install 'cosim[fmi]' (or pip install fmpy)")


@dataclass(frozen=True)
class Variable:
    """One scalar model variable as the subsim uses it."""

    name: str
    vr: int
    type: str
    causality: str
    variability: str
    initial: str | None
    start: str | None
    unit: str
    description: str
    low: float | int | None = None  # its declared min and max (the model description's, or its declared type's)
    high: float | int | None = None
    items: tuple[tuple[str, int], ...] = ()  # an Enumeration's items (name, value), from its declared type


def _bound(v: Any, which: str) -> float | int | None:
    """A variable's declared ``min`` or ``max`` (its own, else its declared type's): an int for an integer type (a
    float would round a 64-bit one)."""
    raw = getattr(v, which, None)
    if raw is None and getattr(v, "declaredType", None) is not None:
        raw = getattr(v.declaredType, which, None)
    try:
        return None if raw is None or isinstance(raw, bool) else int(raw) if v.type in INT_TYPES else float(raw)
    except (TypeError, ValueError):
        return None


@dataclass(frozen=True)
class FmuInfo:
    """What the subsim needs from ``modelDescription.xml``."""

    path: Path
    fmi_version: str  # "2.0" or "3.0"
    model_name: str
    token: str  # FMI 2 guid / FMI 3 instantiationToken
    identifiers: dict[str, str]  # interface ("cs", "me") -> modelIdentifier, only those with a binary here
    can_serialize: dict[str, bool]  # interface -> canSerializeFMUstate
    inputs: tuple[Variable, ...]  # real scalar inputs
    outputs: tuple[Variable, ...]  # real scalar outputs
    settable: dict[str, Variable]  # name -> variable that configure may set (parameters, start values)
    n_states: int
    n_event_indicators: int
    unused: dict[str, str]  # name -> why cosim neither couples nor sets it (arrays, outputs not real, ...)
    fixed_step: bool = False  # co-simulation cannot handle a variable communication step size
    float32_states: tuple[str, ...] = ()  # continuous states (or their derivatives) of FMI 3 type Float32

    @property
    def major(self) -> int:
        return int(self.fmi_version.split(".")[0])

    def summary(self) -> dict[str, Any]:
        """The FMU's metadata as plain data (what ``python -m subsims.fmu X.fmu --describe`` prints)."""
        return {
            "fmu": str(self.path),
            "model": self.model_name,
            "fmi_version": self.fmi_version,
            "interfaces": sorted(self.identifiers),
            "can_save_state": {k: self.can_serialize[k] for k in sorted(self.identifiers)},
            "inputs": {v.name: v.unit for v in self.inputs},
            "outputs": {v.name: v.unit for v in self.outputs},
            "parameters": {v.name: v.start for v in self.settable.values()},
            "fixed_communication_step": self.fixed_step,
            "not_used": dict(self.unused),
        }


@dataclass(frozen=True)
class RealPorts:
    """The value references of a list of real ports, in order, and split by FMI 3 type: a Float32 variable
    must be read and written with fmi3Get/SetFloat32 (FMI 2 has one Real type)."""

    vrs: tuple[int, ...]
    f64_vrs: tuple[int, ...]
    f64_at: tuple[int, ...]  # positions of the Float64 (or FMI 2 Real) ports in ``vrs``
    f32_vrs: tuple[int, ...]
    f32_at: tuple[int, ...]

    @classmethod
    def of(cls, variables: tuple[Variable, ...]) -> RealPorts:
        f32 = [i for i, v in enumerate(variables) if v.type == "Float32"]
        f64 = [i for i, v in enumerate(variables) if v.type != "Float32"]
        return cls(tuple(v.vr for v in variables), tuple(variables[i].vr for i in f64), tuple(f64),
                   tuple(variables[i].vr for i in f32), tuple(f32))


def _say(line: str) -> None:
    """``line`` on stderr; nothing when no one reads it any more (inside the FMU's log callback nothing may raise)."""
    try:
        print(line, file=sys.stderr, flush=True)
    except (OSError, ValueError):  # a closed pipe; a closed stream
        pass


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:300] or type(exc).__name__


def _platform(major: int) -> str:
    return fmpy.platform if major == 2 else fmpy.platform_tuple


def _settable(v: Any, major: int) -> bool:
    if v.dimensions or v.type in {"Binary", "Clock"} or v.variability == "constant":
        return False
    if v.causality == "input":
        return v.type not in REAL_TYPES  # real inputs are ports, driven by the coupling
    if v.causality in {"parameter"}:
        return True
    return v.start is not None and v.initial in {"exact", "approx"} and v.causality in {"local", "output"}


def _items(v: Any) -> tuple[tuple[str, int], ...]:
    """An Enumeration variable's items, (name, value), from its declared type (none if they cannot be read)."""
    declared = getattr(v, "declaredType", None)
    try:
        return tuple((str(i.name), int(i.value)) for i in getattr(declared, "items", None) or ())
    except (TypeError, ValueError):
        return ()


def with_article(word: str) -> str:
    """``word`` with its indefinite article: 'an Integer', 'a Float64'."""
    return f"{'an' if word[:1].lower() in 'aeiou' else 'a'} {word}"


def _unused(v: Any) -> str | None:
    """Why cosim can neither couple nor set ``v``, or None (a port, a settable variable, or nothing to use)."""
    if v.causality == "structuralParameter":  # (FMI 3: it sizes arrays; configuration mode is not run)
        return f"a structural parameter ({v.type}): structural parameters are not supported"
    if v.dimensions:
        return f"an array ({v.type} with dimensions): arrays are not supported"
    if v.causality == "output" and v.type not in REAL_TYPES:
        return f"{with_article(v.type)} output: only real outputs are ports"
    if v.causality in {"input", "parameter"} and v.type in {"Binary", "Clock"}:
        return f"{with_article(v.type)} {v.causality}: {v.type} variables are not supported"
    return None


def read_fmu(path: str | os.PathLike) -> FmuInfo:
    """Read and check an FMU file: a zip with a valid FMI 2.0/3.0 description and a binary for this platform."""
    require_fmpy()
    path = Path(path)
    if not path.is_file():
        raise FmuError(f"{path}: no such FMU file")
    if not zipfile.is_zipfile(path):
        raise FmuError(f"{path}: not an FMU (not a zip archive)")
    try:
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())
    except (zipfile.BadZipFile, OSError) as exc:
        raise FmuError(f"{path}: unreadable zip archive ({_one_line(exc)})") from None
    if "modelDescription.xml" not in names:
        raise FmuError(f"{path}: not an FMU (no modelDescription.xml in the archive)")
    try:
        md = read_model_description(str(path), validate=True)
    except Exception as exc:
        raise FmuError(f"{path}: invalid modelDescription.xml: {_one_line(exc)}") from None
    if md.fmiVersion not in {"2.0", "3.0"}:
        raise FmuError(f"{path}: FMI {md.fmiVersion} is not supported (FMI 2.0 and 3.0 are)")
    major = int(md.fmiVersion[0])
    platform = _platform(major)
    offered: dict[str, str] = {}
    for key, attr in INTERFACES.items():
        interface = getattr(md, attr)
        if interface is not None:
            offered[key] = interface.modelIdentifier
    if not offered:
        only = " (it offers scheduled execution only, which cosim does not run)" if getattr(
            md, "scheduledExecution", None) is not None else ""
        raise FmuError(f"{path}: offers neither co-simulation nor model exchange{only}")
    ext = fmpy.sharedLibraryExtension
    identifiers = {k: i for k, i in offered.items() if f"binaries/{platform}/{i}{ext}" in names}
    if not identifiers:
        have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        wanted = ", ".join(f"binaries/{platform}/{i}{ext}" for i in sorted(set(offered.values())))
        here = sorted(n.rsplit("/", 1)[1] for n in names if n.startswith(f"binaries/{platform}/") and
                      not n.endswith("/"))
        if here:  # a binary named other than the modelIdentifier cannot be loaded by FMI's rules
            raise FmuError(f"{path}: no binary for this platform ({wanted} missing; binaries/{platform}/ holds "
                           f"{', '.join(here)}: the file must be named after the modelIdentifier)")
        if have:
            raise FmuError(f"{path}: no binary for this platform ({wanted} missing; the FMU has binaries for "
                           f"{', '.join(have)})")
        raise FmuError(f"{path}: the FMU has no binaries ({wanted} missing; a source-only FMU must be compiled "
                       "first, e.g. with fmpy.util.compile_platform_binary)")
    variables = [v for v in md.modelVariables if not v.dimensions]
    by_causality = lambda c: tuple(  # noqa: E731
        Variable(v.name, v.valueReference, v.type, v.causality, v.variability, v.initial, v.start,
                 v.unit or (v.declaredType.unit if v.declaredType is not None else None) or "", v.description or "")
        for v in variables if v.causality == c and v.type in REAL_TYPES
    )
    settable = {
        v.name: Variable(v.name, v.valueReference, v.type, v.causality, v.variability, v.initial, v.start,
                         v.unit or "", v.description or "", _bound(v, "min"), _bound(v, "max"),
                         _items(v) if v.type == "Enumeration" else ())
        for v in md.modelVariables if _settable(v, major)
    }
    return FmuInfo(
        path=path.resolve(),
        fmi_version=md.fmiVersion,
        model_name=md.modelName or path.stem,
        token=md.guid or "",
        identifiers=identifiers,
        can_serialize={k: bool(getattr(md, INTERFACES[k]).canSerializeFMUstate) for k in identifiers},
        inputs=by_causality("input"),
        outputs=by_causality("output"),
        settable=settable,
        n_states=int(md.numberOfContinuousStates or 0),
        n_event_indicators=int(md.numberOfEventIndicators or 0),
        unused={v.name: why for v in md.modelVariables if (why := _unused(v))},
        fixed_step="cs" in identifiers and not md.coSimulation.canHandleVariableCommunicationStepSize,
        float32_states=tuple(d.variable.derivative.name if d.variable.derivative is not None else d.variable.name
                             for d in md.derivatives if "Float32" in (d.variable.type, getattr(
                                 d.variable.derivative, "type", None))),
    )


# --- extraction: one directory per FMU file and process, removed at exit (or by a later process) -----

_EXTRACTED: dict[tuple[str, int, int], str] = {}


def extracted(info: FmuInfo) -> str:
    st = info.path.stat()
    key = (str(info.path), st.st_mtime_ns, st.st_size)
    if key not in _EXTRACTED:
        target = tempfile.mkdtemp(dir=process_dir("cosim-fmu-"))
        try:
            fmpy.extract(str(info.path), target)
        except Exception as exc:
            raise FmuError(f"{info.path}: cannot extract ({_one_line(exc)})") from None
        _EXTRACTED[key] = target
    return _EXTRACTED[key]


def check_binaries(info: FmuInfo) -> None:
    """Load (and unload) the binary of each interface, as running it would: FmuError if one cannot load."""
    unzip = extracted(info)
    for kind, identifier in info.identifiers.items():
        cls = fmpy.fmi2.FMU2Slave if info.major == 2 else fmpy.fmi3.FMU3Slave  # loading is the same for ME
        try:
            fmu = cls(guid=info.token, unzipDirectory=unzip, modelIdentifier=identifier, instanceName="check")
        except Exception as exc:
            why = _one_line(exc)
            raise FmuError(f"{info.path}: cannot load the binary of its {kind!r} interface ({why})") from None
        fmu.freeLibrary()


# --- values -------------------------------------------------------------------------------------------

def coerce(var: Variable, value: Any, major: int) -> Any:
    """``value`` as the Python type the FMU variable takes, within its type's range (FMI ``major`` version) and its
    declared min and max; FmuError naming the variable otherwise (a value the FMU's type would wrap or overflow,
    too)."""
    value = _typed(var, value, major)
    if (var.low is not None and value < var.low) or (var.high is not None and value > var.high):
        low = "" if var.low is None else f"{var.low:g}"
        high = "" if var.high is None else f"{var.high:g}"
        raise FmuError(f"{var.name}: {value!r} is outside its declared range [{low}, {high}] (min and max in the "
                       "FMU's model description)")
    return value


def _typed(var: Variable, value: Any, major: int) -> Any:
    if var.type in REAL_TYPES:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
        if ok and var.type == "Float32" and abs(value) > FLOAT32_MAX:
            raise FmuError(f"{var.name} is Float32: {value!r} is beyond its largest finite value, {FLOAT32_MAX:g}")
        if ok:
            return float(value)
        raise FmuError(f"{var.name} is {var.type}: needs a finite number, got {value!r}")
    if var.type == "Enumeration" and isinstance(value, str):  # an item by its name (as an SSP or a user gives it)
        by_name = dict(var.items)
        if value not in by_name:
            known = ", ".join(f"{n} ({v})" for n, v in var.items) or "none declared"
            raise FmuError(f"{var.name} is an Enumeration: {value!r} is none of its items, {known}")
        value = by_name[value]
    if var.type in INT_TYPES:
        if isinstance(value, int) and not isinstance(value, bool):
            low, high = _int_range(var.type, major)
            if not low <= value <= high:
                raise FmuError(f"{var.name} is {var.type}: {value!r} is outside its range [{low}, {high}]")
            return value
        raise FmuError(f"{var.name} is {var.type}: needs an integer, got {value!r}")
    if var.type == "Boolean":
        if isinstance(value, bool):
            return value
        raise FmuError(f"{var.name} is Boolean: needs true or false, got {value!r}")
    if var.type == "String":
        if isinstance(value, str):
            return value
        raise FmuError(f"{var.name} is String: needs a string, got {value!r}")
    raise FmuError(f"{var.name}: variables of type {var.type} cannot be set")


# --- one instance ---------------------------------------------------------------------------------------

class Instance:
    """One instantiated FMU (``kind`` "cs" or "me"), initialized at ``t0`` with ``values`` set first."""

    def __init__(self, info: FmuInfo, kind: str, name: str) -> None:
        self.info, self.kind, self.major = info, kind, info.major
        self.name = name
        self.last_message = ""  # the FMU's latest warning or error logged during the current call
        self.now: float | None = None  # the time of the step being taken (for the FMU's messages)
        self._shown: set[str] = set()  # warnings printed (each distinct one once)
        self.unshown = 0  # warnings not printed: LOG_SHOWN distinct ones were
        self._fmu: Any = None
        unzip = extracted(info)
        cls = {(2, "cs"): fmpy.fmi2.FMU2Slave, (2, "me"): fmpy.fmi2.FMU2Model,
               (3, "cs"): fmpy.fmi3.FMU3Slave, (3, "me"): fmpy.fmi3.FMU3Model}[(self.major, kind)]
        try:
            fmu = cls(guid=info.token, unzipDirectory=unzip, modelIdentifier=info.identifiers[kind],
                      instanceName=name)
        except Exception as exc:
            raise FmuError(f"{info.path}: cannot load the binary ({_one_line(exc)})") from None
        self._fmu = fmu
        self._keep: list[Any] = []
        try:
            if self.major == 2:
                callbacks = fmpy.fmi2.fmi2CallbackFunctions()
                callbacks.logger = fmpy.fmi2.fmi2CallbackLoggerTYPE(self._log2)
                callbacks.allocateMemory = fmpy.fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
                callbacks.freeMemory = fmpy.fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)
                from fmpy.logging import addLoggerProxy

                addLoggerProxy(ctypes.byref(callbacks))
                self._keep.append(callbacks)
                fmu.instantiate(callbacks=callbacks)
            else:
                fmu.instantiate(logMessage=self._log3)
        except Exception as exc:
            self._fmu = None
            raise FmuError(f"{info.path}: cannot instantiate ({self._why(exc)})") from None
        self._ok = True

    # FMU log callbacks. An error is kept for the message of the call that fails with it; a warning (the call's
    # result stands) is printed on stderr, each distinct one once per instance, up to LOG_SHOWN of them: an
    # interval runs several times, and an FMU may warn at every step. Messages with status OK are not shown.
    def _log2(self, env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
        self._logged(status, category, message)

    def _log3(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        self._logged(status, category, message)

    def _logged(self, status: int, category: bytes | None, message: bytes | None) -> None:
        if status < 1:
            return
        text = " ".join((message or b"").decode("utf-8", "replace").split())
        self.last_message = text
        if status != 1:
            return
        if text in self._shown or len(self._shown) >= LOG_SHOWN:
            self.unshown += text not in self._shown
            return
        self._shown.add(text)
        at = "" if self.now is None else f" at t={self.now!r}"
        kind = (category or b"").decode("utf-8", "replace")
        full = len(self._shown) == LOG_SHOWN
        last = f" ({LOG_SHOWN} warnings shown: any more are counted, not shown)" if full else ""
        _say(f"{self.name} ({self.info.path.name}): FMU warning{at}{f' [{kind}]' if kind else ''}: {text}{last}")

    def _why(self, exc: BaseException) -> str:
        msg = _one_line(exc).rstrip(".")
        if self.last_message:
            msg += f": {' '.join(self.last_message.split())[:200]}"
            self.last_message = ""
        return msg

    def call(self, what: str, fn: Any, *args: Any) -> Any:
        self.last_message = ""  # (a message logged by an earlier call is not this one's cause)
        try:
            return fn(*args)
        except Exception as exc:  # FMPy raises FMICallException for a failed call, Exception for others
            raise FmiCallError(f"{what}: {self._why(exc)}", getattr(exc, "status", None) == DISCARD) from None

    # --- life cycle
    def initialize(self, values: dict[str, Any], t0: float, tolerance: float | None) -> None:
        fmu = self._fmu
        if self.major == 2:
            self.call("fmi2SetupExperiment", fmu.setupExperiment, tolerance, t0)
        for name, value in values.items():  # start values and fixed parameters before initialization
            self.set_value(self.info.settable[name], value)
        if self.major == 2:
            self.call("fmi2EnterInitializationMode", fmu.enterInitializationMode)
        else:
            self.call("fmi3EnterInitializationMode", fmu.enterInitializationMode, tolerance, t0)
        self.call("ExitInitializationMode", fmu.exitInitializationMode)
        if self.kind == "me":
            next_event = self._event_iteration()
            if next_event is not None:
                raise FmuError(f"{self.info.path.name}: model exchange: the FMU schedules a time event at "
                               f"t={next_event!r}; events are not handled in model exchange (use its co-simulation "
                               "interface)")
            self.call("EnterContinuousTimeMode", fmu.enterContinuousTimeMode)

    def _event_iteration(self) -> float | None:
        fmu = self._fmu
        for _ in range(1000):
            if self.major == 2:
                info = fmpy.fmi2.fmi2EventInfo()
                self.call("fmi2NewDiscreteStates", fmu.fmi2NewDiscreteStates, fmu.component, ctypes.byref(info))
                more, stop, timed, when = (info.newDiscreteStatesNeeded, info.terminateSimulation,
                                           info.nextEventTimeDefined, info.nextEventTime)
            else:
                more, stop, _, _, timed, when = self.call("fmi3UpdateDiscreteStates", fmu.updateDiscreteStates)
            if stop:
                raise FmiCallError("the FMU asked to terminate during its event iteration")
            if not more:
                return float(when) if timed else None
        raise FmiCallError("the FMU's event iteration did not settle in 1000 rounds")

    def free(self) -> None:
        fmu, self._fmu = self._fmu, None
        if self.unshown:
            _say(f"{self.name} ({self.info.path.name}): {self.unshown} more FMU warning(s) not shown")
            self.unshown = 0
        if fmu is not None:
            try:
                fmu.terminate()
            except Exception:
                pass
            try:
                fmu.freeInstance()
            except Exception:
                pass

    # --- values
    def set_value(self, var: Variable, value: Any) -> None:
        t = var.type
        if self.major == 2:
            setter = {"Real": "setReal", "Integer": "setInteger", "Enumeration": "setInteger",
                      "Boolean": "setBoolean", "String": "setString"}[t]
        else:
            setter = "setInt64" if t == "Enumeration" else f"set{t}"
        self.call(f"setting {var.name}", getattr(self._fmu, setter), [var.vr], [value])

    def set_reals(self, ports: RealPorts, values: np.ndarray) -> None:
        if self.major == 2:
            if ports.vrs:
                self.call("setting the inputs", self._fmu.setReal, list(ports.vrs), [float(x) for x in values])
            return
        for setter, vrs, at in ((self._fmu.setFloat64, ports.f64_vrs, ports.f64_at),
                                (self._fmu.setFloat32, ports.f32_vrs, ports.f32_at)):
            if vrs:
                self.call("setting the inputs", setter, list(vrs), [float(values[i]) for i in at])

    def get_reals(self, ports: RealPorts) -> np.ndarray:
        if self.major == 2:
            if not ports.vrs:
                return np.empty(0)
            return np.array(self.call("getting the outputs", self._fmu.getReal, list(ports.vrs)), dtype=np.float64)
        out = np.empty(len(ports.vrs))
        for getter, vrs, at in ((self._fmu.getFloat64, ports.f64_vrs, ports.f64_at),
                                (self._fmu.getFloat32, ports.f32_vrs, ports.f32_at)):
            if vrs:
                out[list(at)] = self.call("getting the outputs", getter, list(vrs))
        return out

    # --- state
    def serialize(self) -> bytes:
        fmu = self._fmu
        state = self.call("GetFMUstate", fmu.getFMUState)
        try:
            return bytes(self.call("SerializeFMUstate", fmu.serializeFMUState, state))
        finally:
            self.call("FreeFMUstate", fmu.freeFMUState, state)

    def restore(self, data: bytes) -> None:
        fmu = self._fmu
        state = self.call("DeSerializeFMUstate", fmu.deserializeFMUState, data)
        try:
            self.call("SetFMUstate", fmu.setFMUState, state)
        finally:
            self.call("FreeFMUstate", fmu.freeFMUState, state)

    # --- co-simulation
    def do_step(self, t: float, h: float) -> None:
        self.now = t
        if self.major == 2:
            self.call(f"fmi2DoStep at t={t!r}", self._fmu.doStep, t, h, False)
            return
        _, terminate, early, _ = self.call(f"fmi3DoStep at t={t!r}", self._fmu.doStep, t, h, False)
        if terminate or early:
            why = "asked to terminate" if terminate else "returned early"
            raise FmiCallError(f"fmi3DoStep at t={t!r}: the FMU {why}")

    # --- model exchange
    def set_time(self, t: float) -> None:
        self._fmu.setTime(t)

    def set_states(self, x: np.ndarray) -> None:
        x = np.ascontiguousarray(x, dtype=np.float64)
        self._fmu.setContinuousStates(x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), x.size)

    def get_states(self, n: int) -> np.ndarray:
        x = np.zeros(n)
        self.call("GetContinuousStates", self._fmu.getContinuousStates,
                  x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), n)
        return x

    def get_derivatives(self, n: int) -> np.ndarray:
        dx = np.zeros(n)
        get = self._fmu.getDerivatives if self.major == 2 else self._fmu.getContinuousStateDerivatives
        get(dx.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), n)
        return dx

    def set_in_event_mode(self, ports: RealPorts, values: np.ndarray) -> float | None:
        """Set discrete inputs as model exchange allows: in event mode, then the event iteration, then back to
        continuous-time mode. The time of the next time event the FMU then schedules, if any."""
        self.call("EnterEventMode", self._fmu.enterEventMode)
        self.set_reals(ports, values)
        next_event = self._event_iteration()
        self.call("EnterContinuousTimeMode", self._fmu.enterContinuousTimeMode)
        return next_event

    def completed_step(self) -> bool:
        """True when the FMU asks for event mode (not supported in model exchange)."""
        enter, terminate = self.call("CompletedIntegratorStep", self._fmu.completedIntegratorStep, False)
        return bool(enter or terminate)
