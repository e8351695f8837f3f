"""Any FMU (FMI 2.0 / 3.0, co-simulation or model exchange) as a cosim subsim.

Ports: every real scalar input and output of the FMU, one port of width 1 each, named and united as in
``modelDescription.xml`` (the variable's description is the port's doc).

Parameters (``params`` of ``configure`` / a scenario's ``[subsims.<name>.params]``):

- ``fmu``: path of the ``.fmu`` file (not needed when the subsim was started with the path);
- ``interface``: ``"cs"`` (co-simulation, the default when the FMU has it) or ``"me"`` (model exchange);
- ``substeps`` (CS, default 1): communication steps per sample interval; inputs are set from the
  interpolated input segments at every communication point and held over the step;
- ``solver`` (ME, default ``"DOP853"``), ``rtol`` (1e-10), ``atol`` (1e-12), ``max_step`` (none): the
  scipy ``solve_ivp`` settings the subsim integrates a model-exchange FMU with;
- ``start_time`` (0): the time the FMU is initialized at (the scenario's start; the ``fmu =`` shorthand
  and SSP import set it);
- ``tolerance``: the tolerance passed to the FMU's own solver (FMI ``setupExperiment``), if any;
- ``state_capacity``: bytes reserved for the serialized FMU state (default: twice its size at start, at
  least 1 KiB more);
- ``values``: a table ``{variable name: value}`` of parameters and start values; any other key of
  ``params`` is also taken as a variable name. Unknown names are refused with the list of known ones.

State: the subsim's state vector *is* the FMU's serialized state (``fmi2SerializeFMUstate`` /
``fmi3SerializeFMUState``): ``[MAGIC, byte count, 6 bytes per float ...]``, each float an integer below
2**48 so that the vector is finite whatever the bytes. ``advance`` first restores the FMU from the vector,
so it is pure, and the runtime's commit, rollback, ``get_state`` and ``set_state`` work unchanged. An FMU
that cannot serialize its state is refused at ``configure`` (and at start-up when started with its path).
"""

from __future__ import annotations

import copy
import weakref
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from scipy.integrate import BDF, DOP853, LSODA, RK23, RK45, Radau

from cosim.subsim import InputFunction, IntervalTooLong, ModelError, Port, Subsim, closest
from subsims.fmu.fmu import (
    REAL_TYPES,
    FmiCallError,
    FmuError,
    FmuInfo,
    Instance,
    RealPorts,
    coerce,
    read_fmu,
    with_article,
)

SETTINGS = {"fmu", "interface", "substeps", "solver", "rtol", "atol", "max_step", "tolerance", "state_capacity",
            "start_time", "values"}
F32_MAX = float(np.finfo(np.float32).max)
FLOAT32_RTOL = 1e-6  # the tightest rtol a Float32 state can meet (its resolution: 1.2e-7)
CS_ONLY = ("substeps",)  # settings of one interface only
ME_ONLY = ("solver", "rtol", "atol", "max_step")
MAGIC = 46_707_781.0  # first element of every FMU state vector
BYTES_PER_FLOAT = 6
SOLVER_CLASSES = {"RK45": RK45, "RK23": RK23, "DOP853": DOP853, "Radau": Radau, "BDF": BDF, "LSODA": LSODA}
SOLVERS = tuple(SOLVER_CLASSES)


def _other_interface(names: list[str], kind: str, fmu: str) -> str:
    """The refusal of settings for the interface not used."""
    if kind == "cs":
        return (f"{', '.join(names)}: model-exchange setting(s), and {fmu} runs as co-simulation (interface = 'cs'), "
                "stepped by its own solver (its tolerance: 'tolerance'); for cosim's solver: interface = 'me'")
    return (f"{', '.join(names)}: a co-simulation setting, and {fmu} runs as model exchange (interface = 'me'), "
            "integrated by solve_ivp: set solver, rtol, atol or max_step, or interface = 'cs'")


def encode_state(data: bytes, capacity: int) -> np.ndarray:
    """``[MAGIC, len(data), ...]``: the bytes padded to ``capacity``, 6 per float (exact integers < 2**48)."""
    if len(data) > capacity:
        raise ModelError(f"the FMU state grew to {len(data)} bytes, more than the {capacity} reserved at configure; "
                         "set params.state_capacity higher")
    groups = np.zeros((capacity // BYTES_PER_FLOAT, 8), dtype=np.uint8)
    flat = np.frombuffer(data.ljust(capacity, b"\0"), dtype=np.uint8).reshape(-1, BYTES_PER_FLOAT)
    groups[:, :BYTES_PER_FLOAT] = flat
    return np.concatenate(([MAGIC, float(len(data))], groups.view("<u8").ravel().astype(np.float64)))


def decode_state(state: np.ndarray) -> bytes:
    """The bytes :func:`encode_state` packed; ValueError when ``state`` is not such a vector."""
    s = np.asarray(state, dtype=np.float64)
    if s.ndim != 1 or s.size < 2 or s[0] != MAGIC:
        raise ValueError("not an FMU state vector (wrong marker)")
    body = s[2:]
    n = s[1]
    if not (0 <= n <= body.size * BYTES_PER_FLOAT and n == int(n)):
        raise ValueError(f"FMU state vector: byte count {n!r} does not fit its {body.size} floats")
    if not np.all((body >= 0) & (body < 2.0**48) & (body == np.floor(body))):
        raise ValueError("FMU state vector: its floats are not the integers it was packed with")
    raw = body.astype("<u8").view(np.uint8).reshape(-1, 8)[:, :BYTES_PER_FLOAT]
    return raw.tobytes()[: int(n)]


def _capacity(size: int, given: Any) -> int:
    if given is None:
        cap = max(2 * size, size + 1024)
    else:
        if isinstance(given, bool) or not isinstance(given, int) or given < size:
            raise ValueError(f"state_capacity must be an integer of at least {size} (the FMU state's size now), "
                             f"got {given!r}")
        cap = given
    return -(-cap // BYTES_PER_FLOAT) * BYTES_PER_FLOAT


def _free(holder: list) -> None:
    if holder and holder[0] is not None:
        holder[0].free()
        holder[0] = None


class FmuSubsim(Subsim):
    """One FMU as a subsim. ``FmuSubsim("model.fmu")`` reads the FMU at once (its ports are known before
    ``configure``) and serves that file, whatever directory ``params["fmu"]`` names (an external subsim on
    another machine gets the coordinator's path); ``FmuSubsim()`` takes the path from ``params["fmu"]``."""

    name = "fmu"
    caches = ("_step",)  # the communication step of an FMU that cannot change it: the first one it took

    def __init__(self, fmu: str | Path | None = None) -> None:
        self.fmu_path = None if fmu is None else Path(fmu)
        self.info: FmuInfo | None = None
        self.kind = "cs"
        self._holder: list[Instance | None] = [None]
        self._step: list[float] = []
        if self.fmu_path is not None:
            self.info = read_fmu(self.fmu_path)
            self.kind = "cs" if "cs" in self.info.identifiers else "me"
            self._set_ports(self.info)
            if not self.info.can_serialize[self.kind]:
                raise FmuError(self._no_state_message(self.info, self.kind))

    def __deepcopy__(self, memo: dict) -> FmuSubsim:
        """A fresh, unconfigured copy (the runtime copies its prototype at every configure)."""
        new = object.__new__(type(self))
        new.fmu_path, new.info, new.kind, new._holder, new._step = self.fmu_path, self.info, self.kind, [None], []
        for attr in ("inputs", "outputs", "not_ports"):
            if attr in self.__dict__:
                setattr(new, attr, copy.copy(self.__dict__[attr]))
        return new

    @staticmethod
    def _no_state_message(info: FmuInfo, kind: str) -> str:
        flag = "canSerializeFMUstate" if info.major == 2 else "canSerializeFMUState"
        return (f"{info.path.name}: the FMU cannot serialize its state ({flag} is false for "
                f"{'co-simulation' if kind == 'cs' else 'model exchange'}); cosim needs it to re-run an interval "
                "from the committed state, so this FMU is refused")

    def _set_ports(self, info: FmuInfo) -> None:
        self.inputs = {v.name: Port(1, v.unit, v.description) for v in info.inputs}
        self.outputs = {v.name: Port(1, v.unit, v.description) for v in info.outputs}
        held = {v.name: f"{with_article(v.type)} input: only real inputs are ports; give it a value among the "
                "subsim's params (held for the whole run)" for v in info.settable.values()
                if v.causality == "input" and v.type not in REAL_TYPES}
        self.not_ports = {**held, **info.unused}  # (said when a coupling names one)

    # --- configure --------------------------------------------------------------------------------

    def initial_state(self, params: Mapping[str, Any]) -> np.ndarray:
        params = dict(params)
        path = params.get("fmu", self.fmu_path)
        if path is None:
            raise ValueError("fmu: the path of the .fmu file is required")
        if not isinstance(path, (str, Path)):
            raise ValueError(f"fmu must be a path, got {path!r}")
        if self.info is not None and self.fmu_path is not None:  # started with a path: that FMU is served
            if Path(path).name != self.fmu_path.name:
                raise ValueError(f"this subsim serves {self.fmu_path.name} (given when it started); params.fmu "
                                 f"names {Path(path).name}")
            info = self.info  # params.fmu may be the coordinator's path of the same file (external subsims)
        else:
            if not Path(path).is_file():  # perhaps an external subsim, given the coordinator's path on its machine
                raise FmuError(f"{path}: no such FMU file on this machine; a subsim on another machine than the "
                               f"coordinator serves its own copy: python -m subsims.fmu /local/path/{Path(path).name} "
                               "--connect ... --run ... --name ... (docs/fmi.md)")
            info = read_fmu(path)
        kind = params.get("interface", "cs" if "cs" in info.identifiers else "me")
        if kind not in info.identifiers:
            offered = ", ".join(f"{k!r}" for k in sorted(info.identifiers))
            raise ValueError(f"interface {kind!r} not available in {info.path.name}; it offers {offered}")
        if not info.can_serialize[kind]:  # (the FMU, not a parameter, is at fault: not "bad parameter")
            raise ModelError(self._no_state_message(info, kind))
        other = sorted(k for k in params if k in (ME_ONLY if kind == "cs" else CS_ONLY))
        if other:  # (they were taken and did nothing: an FMI probe)
            raise ValueError(_other_interface(other, kind, info.path.name))
        self.substeps = self._int(params.get("substeps", 1), "substeps")
        self.solver = params.get("solver", "DOP853")
        if self.solver not in SOLVERS:
            raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {self.solver!r}")
        self.rtol = self._positive(params.get("rtol", 1e-10), "rtol")
        if kind == "me" and info.float32_states and self.rtol < FLOAT32_RTOL:
            # an FMI probe: the two-mass scenario, 1 s, 142 s at rtol 1e-10 against 2.1 s at 1e-6, in the same stages
            given = "" if "rtol" in params else " (the default)"
            raise ValueError(f"{info.path.name}: its state(s) {', '.join(info.float32_states)} are Float32 (about 7 "
                             f"digits), so model exchange cannot meet rtol = {self.rtol:g}{given}: the solver grinds "
                             f"through ever smaller steps; give rtol >= {FLOAT32_RTOL:g} and a coupling tol above "
                             "it, or interface = 'cs'")
        self.atol = self._positive(params.get("atol", 1e-12), "atol")
        max_step = params.get("max_step")
        self.max_step = np.inf if max_step is None else self._positive(max_step, "max_step")
        start_time = params.get("start_time", 0.0)
        if isinstance(start_time, bool) or not isinstance(start_time, (int, float)) or not np.isfinite(start_time):
            raise ValueError(f"start_time must be a finite number, got {start_time!r}")
        tolerance = params.get("tolerance")
        tolerance = None if tolerance is None else self._positive(tolerance, "tolerance")
        values = self._values(info, params)
        if kind == "me" and info.n_event_indicators:
            raise ValueError(f"{info.path.name}: model exchange with event indicators ({info.n_event_indicators}) "
                             "is not supported (use interface = 'cs')")
        self.info, self.kind, self.fmu_path = info, kind, info.path
        self._set_ports(info)
        self._in_ports = RealPorts.of(info.inputs)
        self._out_ports = RealPorts.of(info.outputs)
        # model exchange sets a discrete input only in event mode: once an interval, at its start (FMI: a discrete
        # input changes at events only); the continuous ones wherever the solver evaluates the FMU
        self._discrete_at = [i for i, v in enumerate(info.inputs) if v.variability == "discrete"]
        # (None: every input is continuous, taken as the input rows are, without a copy per right-hand side)
        self._continuous_at = [i for i, v in enumerate(info.inputs) if v.variability != "discrete"] \
            if self._discrete_at else None
        self._f32_at = list(self._in_ports.f32_at)
        self._in_discrete = RealPorts.of(tuple(info.inputs[i] for i in self._discrete_at))
        self._in_continuous = self._in_ports if self._continuous_at is None else RealPorts.of(
            tuple(info.inputs[i] for i in self._continuous_at))
        _free(self._holder)
        try:
            inst = Instance(info, kind, self.name)
        except (FmiCallError, FmuError) as exc:  # its binary would not load or instantiate
            raise ModelError(str(exc)) from None
        self._holder[0] = inst
        weakref.finalize(self, _free, self._holder)
        try:
            inst.initialize(values, start_time, tolerance)
        except FmiCallError as exc:  # most often a value it refused: its own message says
            _free(self._holder)
            raise ValueError(f"{info.path.name}: initialization failed: {exc}") from None
        except FmuError:
            _free(self._holder)
            raise
        try:
            data = inst.serialize()
        except FmiCallError as exc:  # the FMU, not a parameter: its description promised this
            _free(self._holder)
            raise ModelError(f"{info.path.name}: the FMU could not save its state, though its description says it "
                             f"can: {exc}") from None
        self.capacity = _capacity(len(data), params.get("state_capacity"))
        return encode_state(data, self.capacity)

    @staticmethod
    def _int(value: Any, what: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{what} must be a positive integer, got {value!r}")
        return value

    @staticmethod
    def _positive(value: Any, what: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0 or not np.isfinite(value):
            raise ValueError(f"{what} must be a positive number, got {value!r}")
        return float(value)

    @staticmethod
    def _values(info: FmuInfo, params: Mapping[str, Any]) -> dict[str, Any]:
        given = {k: v for k, v in params.items() if k not in SETTINGS}
        table = params.get("values", {})
        if not isinstance(table, Mapping):
            raise ValueError(f"values must be a table of variable name -> value, got {table!r}")
        both = sorted(set(given) & set(table))
        if both:
            raise ValueError(f"{both} given both in params and in params.values")
        given.update(table)
        ports = sorted(k for k in given if k in {v.name for v in info.inputs})
        if ports:
            what = "is a real input" if len(ports) == 1 else "are real inputs"
            raise ValueError(f"{ports} in {info.path.name} {what}: a port, fed by a coupling or held constant in "
                             f"the scenario's [subsims.<name>.inputs] ({ports[0]} = [value]), not a parameter")
        unused = sorted(k for k in given if k in info.unused)
        if unused:
            raise ValueError(f"{unused[0]} in {info.path.name} is {info.unused[unused[0]]}")
        unknown = sorted(k for k in given if k not in info.settable)
        outputs = sorted(k for k in unknown if k in {v.name for v in info.outputs})
        if outputs:
            what = "is an output" if len(outputs) == 1 else "are outputs"
            rest = [k for k in unknown if k not in outputs]
            also = f"; unknown too: {rest}" if rest else ""
            raise ValueError(f"{outputs} in {info.path.name} {what}, which the FMU computes: not a parameter{also}; "
                             f"settable: {', '.join(sorted(info.settable)) or 'none'}")
        if unknown:
            known = ", ".join(sorted(info.settable)) or "none"
            close = {k: match for k in unknown if (match := closest(k, [*info.settable, *SETTINGS]))}
            hint = (f" (did you mean {close[unknown[0]]!r}?)" if len(unknown) == 1 and close else
                    f" (did you mean {', '.join(f'{m!r} for {k!r}' for k, m in close.items())}?)" if close else "")
            raise ValueError(f"unknown FMU variable(s) {unknown} in {info.path.name}{hint}; settable: {known} "
                             f"(subsim settings: {', '.join(sorted(SETTINGS))})")
        same: dict[int, str] = {}  # value reference -> the name it was given under
        for k in sorted(given):
            var = info.settable[k]
            if (vr := var.vr) in same and info.settable[same[vr]].type == var.type:
                raise ValueError(f"{same[vr]!r} and {k!r} in {info.path.name} are one variable (aliases): give one")
            same[vr] = k
        return {k: coerce(info.settable[k], v, info.major) for k, v in given.items()}

    # --- advance ----------------------------------------------------------------------------------

    def advance(self, state: np.ndarray, times: np.ndarray, u: InputFunction) -> tuple[dict, np.ndarray]:
        inst = self._holder[0]
        if inst is None:
            raise ModelError("the FMU is not instantiated (configure failed?)")
        try:
            data = decode_state(state)
        except ValueError as exc:
            raise ModelError(str(exc)) from None
        if self.kind == "cs" and self.info is not None and self.info.fixed_step and times.size > 1:
            self._same_step(float(times[1] - times[0]) / self.substeps)
        try:
            inst.restore(data)
            if self.kind == "cs":
                outputs = self._advance_cs(inst, times, u)
            else:
                outputs = self._advance_me(inst, times, u)
            end = inst.serialize()
        except FmiCallError as exc:  # a discarded step: the interval again, shorter (with "auto" or max_halvings)
            raise (IntervalTooLong if exc.discard else ModelError)(str(exc)) from None
        names = [v.name for v in self.info.outputs]
        return {n: outputs[:, i : i + 1] for i, n in enumerate(names)}, encode_state(end, self.capacity)

    def _same_step(self, step: float) -> None:
        """Refuse another communication step than the first for an FMU that cannot change it (an FMI probe: an
        automatic interval, or a halving, stepped it anyway: an FMU with a fixed-step solver fails, or ignores it)."""
        if not self._step:
            self._step.append(step)
        elif abs(step - self._step[0]) > 1e-9 * self._step[0]:
            assert self.info is not None
            raise ModelError(f"{self.info.path.name} cannot change its communication step "
                             "(canHandleVariableCommunicationStepSize is false): it stepped "
                             f"{self._step[0]:.9g} s, this interval asks {step:.9g} s; give it a fixed [coupling] "
                             "interval (not \"auto\") and max_halvings = 0")

    def _input_matrix(self, u: InputFunction, points: np.ndarray) -> np.ndarray:
        """Inputs at ``points`` (k,), one column per FMU input: one call of ``u`` on the array of times where
        the runtime supports it, else one call per point (the subsim API documents both)."""
        if not self._in_ports.vrs:
            return np.zeros((points.size, 0))
        names = [v.name for v in self.info.inputs]
        try:
            values = u(points)
            cols = [np.asarray(values[n], dtype=np.float64) for n in names]
            if all(c.shape == (points.size, 1) for c in cols):
                return self._in_float32_range(np.hstack(cols), points)
        except (TypeError, ValueError, IndexError):
            pass
        rows = [u(float(t)) for t in points]
        return self._in_float32_range(np.array([[float(np.asarray(r[n]).reshape(-1)[0]) for n in names]
                                                for r in rows]), points)

    def _in_float32_range(self, inputs: np.ndarray, points: np.ndarray) -> np.ndarray:
        """``inputs``, unless one for a Float32 input is beyond Float32's range: that FMU input would be inf (and
        its outputs blamed for it: an FMI probe)."""
        at = self._f32_at
        if at and not (np.abs(inputs[:, at]) <= F32_MAX).all():
            row, col = np.argwhere(~(np.abs(inputs[:, at]) <= F32_MAX))[0]
            raise ModelError(f"input {self.info.inputs[at[col]].name} = {float(inputs[row, at[col]])!r} at t = "
                             f"{float(points[row])!r} is beyond the largest Float32 ({F32_MAX:.4g}), the type of that "
                             "FMU input")
        return inputs

    def _advance_cs(self, inst: Instance, times: np.ndarray, u: InputFunction) -> np.ndarray:
        m = self.substeps
        if m == 1:
            points = np.asarray(times, dtype=np.float64)
        else:
            fine = [np.linspace(a, b, m + 1)[:-1] for a, b in zip(times[:-1], times[1:])]
            points = np.concatenate([*fine, times[-1:]])
        inputs = self._input_matrix(u, points)
        out = np.empty((times.size, len(self._out_ports.vrs)))
        for j in range(points.size - 1):
            inst.set_reals(self._in_ports, inputs[j])
            if j % m == 0:
                out[j // m] = inst.get_reals(self._out_ports)
            inst.do_step(float(points[j]), float(points[j + 1] - points[j]))
        inst.set_reals(self._in_ports, inputs[-1])
        out[-1] = inst.get_reals(self._out_ports)
        return out

    def _advance_me(self, inst: Instance, times: np.ndarray, u: InputFunction) -> np.ndarray:
        n = self.info.n_states
        t0, t1 = float(times[0]), float(times[-1])
        continuous = self._continuous_at
        if self._discrete_at:  # (fmi2SetReal refused them in continuous-time mode: an FMI probe, Feedthrough)
            held = self._input_matrix(u, np.array([t0]))[0][self._discrete_at]
            inst.set_time(t0)
            next_event = inst.set_in_event_mode(self._in_discrete, held)
            if next_event is not None:
                raise ModelError(f"the FMU schedules a time event at t={next_event!r} after its discrete inputs were "
                                 "set; model exchange events are not supported (use interface = 'cs')")

        def at(t: float, x: np.ndarray) -> None:  # the FMU at time t, in state x, with the inputs there
            inst.set_time(t)
            row = self._input_matrix(u, np.array([t]))[0]
            inst.set_reals(self._in_continuous, row if continuous is None else row[continuous])
            inst.set_states(x)

        def rhs(t: float, x: np.ndarray) -> np.ndarray:
            at(t, x)
            return inst.get_derivatives(n)

        if n == 0:  # no continuous states: outputs are functions of time and inputs
            states = np.zeros((0, times.size))
        else:
            try:
                states = self._integrate(inst, rhs, at, inst.get_states(n), times)
            except (FmiCallError, ModelError):
                raise
            except Exception as exc:  # an FMI call inside the right-hand side failed
                raise FmiCallError(f"model exchange right-hand side: {inst._why(exc)}") from None
        inputs = self._input_matrix(u, np.asarray(times, dtype=np.float64))
        out = np.empty((times.size, len(self._out_ports.vrs)))
        for i, t in enumerate(times):
            inst.set_time(float(t))
            inst.set_reals(self._in_continuous, inputs[i] if continuous is None else inputs[i][continuous])
            if n:
                inst.set_states(states[:, i])
            out[i] = inst.get_reals(self._out_ports)
        if n == 0 and inst.completed_step():
            raise ModelError(f"the FMU asks for event handling at t={t1!r}; model exchange events are not supported "
                             "(use interface = 'cs')")
        return out

    def _integrate(self, inst: Instance, rhs: Any, at: Any, x0: np.ndarray, times: np.ndarray) -> np.ndarray:
        """The states at ``times`` (n x samples), as ``solve_ivp(..., t_eval=times)`` gives them (the same steps and
        dense output), and after every accepted step fmiCompletedIntegratorStep, at that step's end, as FMI asks:
        an FMU that wants event mode then is refused there, not at the interval's end."""
        solver = SOLVER_CLASSES[self.solver](rhs, float(times[0]), x0, float(times[-1]), rtol=self.rtol,
                                             atol=self.atol, max_step=self.max_step)
        columns, k = [], 0
        while k < times.size:
            message = solver.step()
            if solver.status == "failed":
                raise ModelError(f"solve_ivp ({self.solver}) failed: {message}")
            upto = int(np.searchsorted(times, solver.t, side="right"))
            if upto > k:
                columns.append(solver.dense_output()(times[k:upto]))
                k = upto
            at(solver.t, solver.y)
            if inst.completed_step():
                raise ModelError(f"the FMU asks for event handling at t={float(solver.t)!r} (a step event); model "
                                 "exchange events are not supported (use interface = 'cs')")
            if solver.status == "finished":
                break
        return np.hstack(columns)
