"""The subsim runtime: owns committed state and time, the latest trial and the committed history.

It serves the nine commands for one model, identically whether called in-process or from the bus.
Every command either succeeds or raises ``CosimError`` with nothing committed changed.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import itertools
import math
import os
import re
import time
import traceback
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any, NamedTuple, NoReturn

import numpy as np

from cosim.contract import PROTOCOL_VERSION, CosimError
from cosim.importing import code_digests, own_frame
from cosim.signals import SegmentError, all_finite, check_scheme, check_time_grid, interpolant
from cosim.subsim import IntervalTooLong, ModelError, Port, Subsim, as_ports, resolve_params

DEFAULT_HISTORY = 32
_FLOAT64 = np.dtype(np.float64)


class _Trial(NamedTuple):  # one per run_interval: a tuple costs a fraction of a frozen dataclass
    epoch: int  # committed epoch the trial started from
    end_time: float
    end_state: np.ndarray


def _model_frames(exc: BaseException) -> str:
    """The traceback of an exception raised by a model: its own frames (the runtime's frame that called it left out)."""
    tb = exc.__traceback__.tb_next if exc.__traceback__ is not None else None
    return "".join(traceback.format_exception(type(exc), exc, tb))


def _model_exception(where: str, exc: BaseException) -> CosimError:
    """A model's unexpected exception as an error that names it in one line, with the line of the model's own
    code it came from (a test's failure shows where), and carries the model's own frames."""
    line = _model_line(exc)
    hint = ""
    if isinstance(exc, ValueError) and "read-only" in str(exc):  # numpy's words for a write into the state given
        hint = ": the state and inputs advance() is given are read-only; change a copy (x = state.copy())"
    call = where if " " in where else f"{where}()"  # (a description, not a name to call)
    return CosimError("model_exception", f"{call} raised {type(exc).__name__}: {exc}{line}{hint}",
                      _model_frames(exc))


ATTRIBUTES_WATCHED = 3  # run_intervals after a configure whose model attributes are compared with the configured ones
WATCH_EVERY = 16  # and after those, every this many (a mode flag on self that latches late)...
WATCH_SHARE = 0.01  # ...made rarer (the period doubled) while a look costs more than this share of the runs between
RERUN_LIMIT = 1.0  # s: a first run after configure quicker than this is made twice (a slower one: its deadline)
MARKED_WHOLE = 1 << 16  # bytes: a larger array attribute is marked by a digest (the marks are kept for the whole run)


VALUES = (bool, int, float, complex, str, bytes, tuple, frozenset, type(None))  # compared by value


def _attribute_marks(model: object, whole: int = 0) -> dict[str, Any]:
    """What tells a model's attribute changed (:func:`_mark` of each, but for the caches it declares);
    :func:`_changed_attributes` compares two. ``whole``: bytes up to which an array is kept as its bytes (above: a
    digest of them; 0: DIGESTED)."""
    caches = set(getattr(model, "caches", ())) | _cached_properties(type(model))
    return {k: _marked(v, whole) for k, v in vars(model).items() if k not in caches}


@functools.lru_cache(maxsize=64)
def _cached_properties(cls: type) -> frozenset[str]:
    """The names of a class's functools.cached_property attributes: computed once from the instance, a cache (one
    reached first late in a run was refused as a changed attribute: a review)."""
    return frozenset(k for c in cls.__mro__ for k, v in vars(c).items() if isinstance(v, functools.cached_property))


def _marked(v: Any, whole: int = 0) -> Any:
    try:
        return _mark(v, _Budget(whole), ())
    except Exception:  # an object that cannot be looked into (a released memoryview, a __len__ raising): itself
        return _Ref(v)


class _Budget:
    """How much of one attribute is looked into: past it, a container is marked as itself (what it holds unseen)."""

    __slots__ = ("items", "nbytes", "whole")

    def __init__(self, whole: int = 0) -> None:
        self.items, self.nbytes = 20_000, 1 << 30
        self.whole = whole or DIGESTED  # bytes of an array kept as they are; above, a digest

    def take(self, items: int = 0, nbytes: int = 0) -> bool:
        if items > self.items or nbytes > self.nbytes:
            return False
        self.items, self.nbytes = self.items - items, self.nbytes - nbytes
        return True


class _Ref:
    """An object marked as itself: the same only if it is that object."""

    __slots__ = ("obj",)

    def __init__(self, obj: Any) -> None:
        self.obj = obj

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _Ref) and other.obj is self.obj

    __hash__ = None  # type: ignore[assignment]


_NAN = ("nan",)  # every NaN's mark: a NaN bound anew is the same value
DEPTH = 32  # levels of containers looked into


def _mark(v: Any, budget: _Budget, within: tuple[int, ...]) -> Any:
    """A value by its value (an array by its bytes); a list, tuple, deque, dict or set, of any subclass, by its
    items' marks (so an item appended or changed in place shows); any other object as itself (what a helper object
    or an FMU's instance holds is not looked into: ``advance`` may be pure while it changes inside). ``within``: the
    ids of the containers it is in (a cycle, and more than DEPTH levels, end in identity)."""
    if isinstance(v, np.ndarray):
        if not budget.take(nbytes=v.nbytes) and within:
            return _Ref(v)
        return ("array", v.dtype.str, v.shape, _contents(v, budget.whole))
    if isinstance(v, (float, np.floating)):
        return _NAN if v != v else v
    if isinstance(v, (bytearray, memoryview)):
        return ("bytes", _contents(np.frombuffer(v, np.uint8), budget.whole)) if budget.take(nbytes=len(v)) \
            else _Ref(v)
    if isinstance(v, VALUES + (np.generic,)) and not isinstance(v, (tuple, frozenset)):
        return v
    if id(v) in within or len(within) >= DEPTH:
        return _Ref(v)
    if isinstance(v, (list, tuple, deque, dict, set, frozenset)) and budget.take(items=len(v)):
        inside = (*within, id(v))
        if isinstance(v, dict):
            return ("dict", {k: _mark(x, budget, inside) for k, x in v.items()})
        if isinstance(v, (set, frozenset)):
            return ("set", frozenset(v))
        return (type(v).__name__, [_mark(x, budget, inside) for x in v])
    return v if isinstance(v, VALUES) else _Ref(v)


DIGESTED = 64 << 20  # bytes: a larger array is compared by a BLAKE2 digest of its bytes, not a copy of them


def _contents(a: np.ndarray, whole: int = DIGESTED) -> bytes:
    """What an array holds, as bytes to compare: a copy of them, or above ``whole`` bytes a digest (no copy)."""
    if a.nbytes <= whole or a.dtype.hasobject:
        return a.tobytes()
    flat = np.ascontiguousarray(a).reshape(-1).view(np.uint8)  # (any dtype: datetime64 is no buffer of its own)
    return hashlib.blake2b(flat.data, digest_size=16).digest()


def _changed_attributes(before: Mapping[str, Any], after: Mapping[str, Any]) -> list[str]:
    """The names of the attributes whose :func:`_attribute_marks` differ (added and removed ones included)."""
    return sorted(k for k in set(before) | set(after) if k not in before or k not in after or not _same(before[k],
                                                                                                       after[k]))


def _same(a: Any, b: Any) -> bool:
    if a is b:  # (a NaN is not equal to itself)
        return True
    try:
        return bool(a == b)
    except Exception:  # (an item's own __eq__ failing)
        return False


def output_bits(outputs: Mapping[str, Any]) -> tuple[tuple[str, bytes], ...]:
    """What advance()'s outputs hold, bit for bit, to compare two answers (the runtime's repeated first run,
    :func:`cosim.check_pure`)."""
    return tuple(sorted((k, np.asarray(v, dtype=np.float64).tobytes()) for k, v in outputs.items()))


def _same_outputs(again: Any, outputs: Mapping[str, np.ndarray]) -> bool:
    """Whether ``again``, what advance() returned a second time, holds the outputs of the checked first answer."""
    try:
        return output_bits(again[0]) == output_bits(outputs)
    except (TypeError, ValueError, AttributeError, KeyError, IndexError):  # not even of the first answer's form
        return False


def float_samples(port: str, value: Any) -> np.ndarray:
    """Input samples as float64, or a ``bad_value`` CosimError naming ``inputs.<port>``: nothing that is no array of
    real numbers (a complex one included: a cast would drop its imaginary part with only a warning)."""
    try:
        if np.iscomplexobj(value):
            raise TypeError("complex")
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise CosimError("bad_value", f"inputs.{port}: not a float array") from None


def maker_name(factory: Any) -> str:
    """What makes a model, as a call names it: ``Boom`` for the class or ``partial(Boom, 2)``, else what it is."""
    made = getattr(factory, "func", factory)  # (functools.partial)
    name = getattr(made, "__name__", "")
    return name if name.isidentifier() else ""


def _model_line(exc: BaseException) -> str:
    """`` (file.py:12 in helper)``: the innermost frame of the model's own code (the runtime's frame left out)."""
    frame = own_frame(exc)
    return f" ({os.path.basename(frame.filename)}:{frame.lineno} in {frame.name})" if frame is not None else ""


class _Inputs(dict):
    """What a model's ``u(t)`` returns: a dict whose missing key names the inputs there are (a bare KeyError 'Temp'
    did not)."""

    def __missing__(self, key: object) -> NoReturn:
        raise KeyError(f"{key!r} is no input of this subsim; its inputs: {', '.join(map(repr, self)) or 'none'}")


def _naming(said: str, given: Mapping[str, Any]) -> str:
    """A model's refusal of its parameters that names none of them ("could not convert string to float: 'x'"),
    with the one whose value holds what it quotes, or else the names given."""
    if not given or any(re.search(rf"(?<!\w){re.escape(str(k))}(?!\w)", said) for k in given):  # (as a word: 'k')
        return said
    quoted = re.findall(r"'([^']*)'", said)
    hits = [k for k, v in given.items() if any(f"'{q}'" in repr(v) for q in quoted)]
    if len(hits) == 1:
        return f"{said} (parameter {hits[0]!r} = {given[hits[0]]!r})"
    return f"{said} (parameters given: {', '.join(map(str, given))})"


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


class _InputLayout(NamedTuple):
    """Which columns of the one array a request's input samples are joined into hold each input (made once per
    configure, not per request)."""

    ports: Mapping[str, Port] | None  # the input ports it was made for
    slices: tuple[tuple[str, slice], ...]

    @classmethod
    def of(cls, ports: Mapping[str, Port]) -> _InputLayout:
        ends = itertools.accumulate(p.size for p in ports.values())
        return cls(ports, tuple((k, slice(end - p.size, end)) for (k, p), end in zip(ports.items(), ends)))


def _port_map(ports: Mapping[str, Port]) -> dict[str, dict]:
    return {k: {"size": p.size, "unit": p.unit, "doc": p.doc} for k, p in ports.items()}


ModelFactory = Callable[[], Subsim]


def as_factory(model: Subsim | ModelFactory) -> ModelFactory:
    """A zero-argument callable making fresh model instances. An instance given is a prototype: each
    ``configure`` works on a deep copy of it, so constructor arguments carry over and a failed
    configure leaves the running model untouched."""
    if isinstance(model, Subsim):
        return lambda: copy.deepcopy(model)
    if callable(model):
        return model
    raise TypeError(f"a subsim model must be a Subsim instance or a factory making one, got {model!r}")


MODEL_FAULTS = frozenset({"model_error", "too_long", "model_exception"})  # codes that are the model's, not the caller's


class Runtime:
    """Commit/rollback bookkeeping around one :class:`Subsim` model.

    ``model`` is a :class:`Subsim` instance (a prototype, copied at each ``configure``) or a
    zero-argument factory such as the class itself or ``functools.partial(MyModel, path)``.
    """

    def __init__(
        self, model: Subsim | ModelFactory, name: str | None = None, history_limit: int = DEFAULT_HISTORY
    ) -> None:
        self._factory = as_factory(model)
        try:
            model = self._new_model()
        except Exception as exc:  # a model that cannot be built (a licence, a file, a bug): one line, its own frames
            if isinstance(model, Subsim):  # a prototype, copied for each configure
                raise CosimError("model_exception", f"copying the {type(model).__name__} instance given (each "
                                 f"configure works on a copy) raised {type(exc).__name__}: {exc}{_model_line(exc)}",
                                 _model_frames(exc)) from None
            raise _model_exception(maker_name(model) or "the model factory", exc) from None
        self.model = model
        self.name = name or model.name
        self.history_limit = history_limit
        self.inputs: dict[str, Port] = as_ports(model.inputs)
        self.outputs: dict[str, Port] = as_ports(model.outputs)
        self.time: float | None = None
        self.state: np.ndarray | None = None
        self.history: deque[tuple[float, np.ndarray]] = deque(maxlen=history_limit)
        self.trial: _Trial | None = None
        self.epoch = 0
        self.requests = 0
        self.shutdown_requested = False
        self._configured_marks: dict[str, Any] | None = None  # the model's attributes as configure left them
        self._runs = 0  # run_intervals since the configure
        self._watch_every = WATCH_EVERY  # runs between looks at them, after the first ATTRIBUTES_WATCHED
        self._next_look = 0  # the run after which they are looked at next (beyond the first ones)
        self._looked = 0.0  # when the latest look ended (perf_counter)
        self._watched_until: float | None = None  # the end of the latest run whose attributes were compared
        self._rerun_checked = True  # whether a run since the configure was repeated and gave the same bits
        self._input_layout = _InputLayout(None, ())
        self._grid: tuple[np.ndarray, float, float] = (np.empty(0), 0.0, 0.0)  # the latest request's checked times,
        self._grid_bytes: bytes | None = None  # first, last; and the bytes they were checked from (None: none yet)
        # told of every error the model caused (model_error, model_exception), e.g. to show it to the model's
        # owner at the subsim's own terminal as well as in the coordinator's reply
        self.on_model_error: Callable[[str, CosimError], None] | None = None
        self._commands: dict[str, Callable[..., dict]] = {
            "describe": self.describe,
            "configure": self.configure,
            "run_interval": self.run_interval,
            "commit": self.commit,
            "rollback": self.rollback,
            "get_state": self.get_state,
            "set_state": self.set_state,
            "status": self.status,
            "shutdown": self.shutdown,
        }

    @property
    def model_id(self) -> str:
        cls = type(self.model)
        return f"{cls.__module__}.{cls.__qualname__}"

    def handle(self, cmd: str, args: Mapping[str, Any]) -> dict:
        """Run one decoded command. Raises ``CosimError`` only."""
        self.requests += 1
        fn = self._commands.get(cmd)
        if fn is None:
            raise CosimError("unknown_command", f"unknown command {cmd!r}")
        try:
            return fn(**args)
        except CosimError as exc:
            if self.on_model_error is not None and exc.code in MODEL_FAULTS:
                self.on_model_error(cmd, exc)
            raise
        except TypeError as exc:  # wrong keyword arguments from an in-process caller
            raise CosimError("bad_request", f"{cmd}: {exc}") from None

    # --- commands -----------------------------------------------------------------------------

    def describe(self) -> dict:
        return {
            "name": self.name,
            "model": self.model_id,
            "inputs": _port_map(self.inputs),
            "outputs": _port_map(self.outputs),
            "algebraic": bool(self.model.algebraic),
            "configured": self.state is not None,
            "time": self.time,
            "history_limit": self.history_limit,
            "protocol": PROTOCOL_VERSION,
            "params": {k: {"default": p.default, "unit": p.unit, "doc": p.doc} for k, p in self.model.params.items()},
            "code": code_digests(type(self.model).__module__),
            **({"not_ports": dict(self.model.not_ports)} if self.model.not_ports else {}),
        }

    def configure(self, params: Mapping[str, Any], t0: float = 0.0) -> dict:
        """Fresh model instance from ``params``; the old configuration stays if this fails."""
        t0 = self._finite_float(t0, "t0")
        try:
            model = self._new_model()
        except Exception as exc:  # the constructor (or the copy of a prototype) of a model that did build once
            raise _model_exception(type(self.model).__qualname__, exc) from None
        if model.name != self.name:  # the name it is served under (an FMU's instance name, in its messages)
            try:
                model.name = self.name
            except AttributeError:  # a read-only property of the model's own
                pass
        try:
            resolved = resolve_params(model.params, params)
        except ValueError as exc:
            raise CosimError("bad_value", f"configure: bad parameter: {exc}") from None
        try:
            state = model.initial_state(resolved)
            inputs, outputs = as_ports(model.inputs), as_ports(model.outputs)
        except ModelError as exc:
            raise CosimError("model_error", f"configure: {exc}") from None
        except ValueError as exc:  # the model refusing a parameter, as the contract asks
            raise CosimError("bad_value", f"configure: bad parameter: {_naming(str(exc), params)}") from None
        except (KeyError, TypeError) as exc:  # a refusal too, or a bug (a KeyError 'K'): its frames tell which
            said = _naming(f"{type(exc).__name__}: {exc}", params)
            raise CosimError("bad_value", f"configure: bad parameter (or a bug in initial_state()): {said}",
                             _model_frames(exc)) from None
        except Exception as exc:
            raise _model_exception("initial_state", exc) from None
        try:
            state = self._check_state(state, None, "initial_state() for these parameters gave a state that")
        except CosimError as exc:
            raise CosimError(exc.code, _naming(exc.message, params)) from None
        self.model, self.inputs, self.outputs = model, inputs, outputs
        self._set_committed(t0, state)
        self.history.clear()
        self._configured_marks = _attribute_marks(model, MARKED_WHOLE) if hasattr(model, "__dict__") else None
        self._runs, self._watched_until, self._rerun_checked = 0, None, False
        self._watch_every, self._next_look, self._looked = WATCH_EVERY, WATCH_EVERY, time.perf_counter()
        return self.describe()

    def run_interval(self, t: Any, inputs: Mapping[str, Any], interp: str = "linear", commit: bool = False) -> dict:
        """Run the interval ``t`` from the committed state. With ``commit`` the latest trial is committed
        first, in the same request (one round trip less per interval); it is committed only if this run
        succeeds, so a failed request still changes nothing committed."""
        state, t0 = self._require_configured()
        trial = None
        if commit:
            trial = self._committable_trial()
            state, t0 = trial.end_state, trial.end_time
        times, start, end = self._time_grid(t)
        if start != t0 or (t0 == 0.0 and math.copysign(1.0, start) != math.copysign(1.0, t0)):  # -0.0 != 0.0
            what = "the trial to commit ends" if commit else "the committed time is"
            raise CosimError("time_mismatch", f"interval starts at t={start!r} but {what} {t0!r}")
        try:
            check_scheme(interp, times.size)
        except ValueError as exc:
            raise CosimError("bad_value", f"interp: {exc}") from None
        u = self._input_function(times, inputs, interp)
        started = time.perf_counter()
        result = self._advance(state, times, u)
        took = time.perf_counter() - started
        self._runs += 1
        if self._configured_marks is not None and (self._runs <= ATTRIBUTES_WATCHED or self._runs >= self._next_look):
            self._watch_attributes(times)
        if type(result) is not tuple or len(result) != 2:
            got = f"a tuple of {len(result)}" if isinstance(result, tuple) else type(result).__name__
            raise CosimError("model_error", f"advance() must return (outputs, end_state), got {got}")
        outputs, end_state = result
        checked = self._check_outputs(outputs, times)
        end_state = self._check_state(end_state, state.size, "the end state advance() returned", from_model=True,
                                      over=times)
        if not self._rerun_checked:
            self._check_rerun(state, times, u, checked, took)
        if trial is not None:
            self._commit(trial)
        self.trial = _Trial(self.epoch, end, end_state)
        return {"t": times, "outputs": checked, "end_time": end}

    def _time_grid(self, t: Any) -> tuple[np.ndarray, float, float]:
        """``t`` checked as an interval's sample times, read-only (advance() sees what it would remotely), and its
        first and last time. Every stage of an interval runs on one grid: the same times as the previous request's
        give its checked copy again (checked and copied once per interval, not once per stage)."""
        if type(t) is np.ndarray and t.dtype is _FLOAT64 and t.ndim == 1 and t.tobytes() == self._grid_bytes:
            return self._grid
        try:
            times = check_time_grid(t, "t")
        except SegmentError as exc:
            raise CosimError("bad_value", str(exc)) from None
        if times.size < 2:
            raise CosimError("bad_value", f"t must hold at least 2 sample times, got {times.size}")
        times = _readonly(times)  # (a copy of its own even of a read-only array: kept for the next requests)
        self._grid, self._grid_bytes = (times, float(times[0]), float(times[-1])), times.tobytes()
        return self._grid

    def _advance(self, state: np.ndarray, times: np.ndarray, u: Callable) -> Any:
        try:
            return self.model.advance(state, times, u)
        except IntervalTooLong as exc:
            raise CosimError("too_long", f"at t in [{times[0]}, {times[-1]}]: {exc}") from None
        except ModelError as exc:
            raise CosimError("model_error", f"at t in [{times[0]}, {times[-1]}]: {exc}") from None
        except Exception as exc:
            raise _model_exception("advance", exc) from None

    def _watch_attributes(self, times: np.ndarray) -> None:
        """Refuse a model whose attributes are no longer what configure left (but the caches it declares): what
        evolves there is not rolled back, and a repeated stage integrates it again."""
        assert self._configured_marks is not None
        started = time.perf_counter()
        changed = _changed_attributes(self._configured_marks, _attribute_marks(self.model, MARKED_WHOLE))
        since, self._watched_until = self._watched_until, float(times[-1])
        if self._runs >= self._next_look:  # (a model with large arrays: looked at less often, at most 1 % of its time)
            now = time.perf_counter()
            if now - started > WATCH_SHARE * (started - self._looked):
                self._watch_every *= 2
            self._next_look, self._looked = self._runs + self._watch_every, now
        if not changed:
            return
        when = (f"over t in [{times[0]:g}, {times[-1]:g}]" if self._runs <= ATTRIBUTES_WATCHED else
                f"found over t in [{times[0]:g}, {times[-1]:g}], in one of the runs since the look at t = {since:g}")
        raise CosimError("model_error", f"advance() changed the model's attribute(s) {changed} ({when}): what "
                         "evolves belongs in the state vector, which a rollback or a repeated stage restores; "
                         "advance() must depend on its arguments only (what it computes once, initial_state() may keep "
                         "on self; a cache of pure results it fills is declared: caches = ('name',); cosim.check_pure "
                         "tests a model for this)")

    def _check_rerun(self, state: np.ndarray, times: np.ndarray, u: Callable, outputs: Mapping[str, np.ndarray],
                     took: float) -> None:
        """The first run after a configure, when quicker than RERUN_LIMIT, is made twice: the second must give the
        same outputs, bit for bit. A model that steps a helper object of its own (a legacy simulation's instance), or
        a module-level variable, passes the attribute check (a helper object may be reloaded from the state each
        time, which is right) but not this. (Outputs only: an FMU's serialized state may hold bytes it does not
        promise to repeat.)"""
        self._rerun_checked = True
        if took > RERUN_LIMIT:
            return
        checking = (f"over t in [{times[0]:g}, {times[-1]:g}], the first run after configure, made twice to check that "
                    "it gives the same outputs")
        try:
            again = self._advance(state, times, u)
        except CosimError as exc:
            raise CosimError(exc.code, f"advance() called again on the same state, times and inputs ({checking}) "
                             f"failed: {exc.message}", exc.traceback) from None
        if not _same_outputs(again, outputs):
            raise CosimError("model_error", f"advance() gave other outputs when called again on the same state, times "
                             f"and inputs ({checking}): it keeps something between calls outside the state vector (a "
                             "helper object it steps, a module-level variable, a random generator?), or its arithmetic "
                             "differs from call to call (a parallel sum in varying order); every stage and every "
                             "rollback runs advance() again from the committed state, so all that evolves belongs in "
                             "the state vector (docs/tutorial.md, 'Wrapping an existing simulation')")

    def commit(self) -> dict:
        self._require_configured()
        self._commit(self._committable_trial())
        return {"time": self.time}

    def _committable_trial(self) -> _Trial:
        trial = self.trial
        if trial is None:
            raise CosimError("no_trial", "commit without a run_interval since the last commit or rollback")
        if trial.epoch != self.epoch:
            raise CosimError("stale_trial", "the latest trial started from a committed state that has since changed")
        return trial

    def _commit(self, trial: _Trial) -> None:
        self.history.append((self.time, self.state))
        self._set_committed(trial.end_time, trial.end_state)
        self.trial = None

    def rollback(self, to_time: float | None = None) -> dict:
        self._require_configured()
        self.trial = None
        if to_time is None or to_time == self.time:
            return {"time": self.time}
        times = [t for t, _ in self.history]
        if to_time not in times:
            shown = ", ".join(repr(x) for x in times[-5:]) or "none"
            raise CosimError("not_in_history", f"no committed state at t={to_time!r}; latest kept: {shown}")
        while self.history:
            t, s = self.history.pop()
            if t == to_time:
                self._set_committed(t, s)
                break
        return {"time": self.time}

    def get_state(self) -> dict:
        state, t = self._require_configured()
        return {"time": t, "state": state, "model": self.model_id}

    def set_state(self, time: float, state: Any) -> dict:
        current, _ = self._require_configured()
        time = self._finite_float(time, "time")
        new = self._check_state(state, current.size, "state")
        self._set_committed(time, new)
        self.history.clear()
        return {"time": self.time}

    def status(self) -> dict:
        return {
            "name": self.name,
            "configured": self.state is not None,
            "time": self.time,
            "has_trial": self.trial is not None and self.trial.epoch == self.epoch,
            "history": len(self.history),
            "requests": self.requests,
            "pid": os.getpid(),
        }

    def shutdown(self) -> dict:
        self.shutdown_requested = True
        return {}

    # --- helpers ------------------------------------------------------------------------------

    def _new_model(self) -> Subsim:
        model = self._factory()
        if not isinstance(model, Subsim):
            raise TypeError(f"the model factory made {type(model).__name__}, not a cosim.Subsim")
        return model

    def _set_committed(self, time: float, state: np.ndarray) -> None:
        """Replace the committed state by ``state``, a read-only copy of the runtime's own (as
        :meth:`_check_state` returns: kept as it is). A trial run before this is now stale (never committed)."""
        self.time, self.state = float(time), state
        self.epoch += 1

    def _require_configured(self) -> tuple[np.ndarray, float]:
        if self.state is None or self.time is None:
            raise CosimError("not_configured", "configure the subsim first")
        return self.state, self.time

    @staticmethod
    def _finite_float(x: Any, what: str) -> float:
        try:
            f = float(x)
        except (TypeError, ValueError):
            raise CosimError("bad_value", f"{what} must be a number, got {x!r}") from None
        if not math.isfinite(f):
            raise CosimError("bad_value", f"{what} must be finite, got {f!r}")
        return f

    @staticmethod
    def _check_state(state: Any, size: int | None, what: str, from_model: bool = False,
                     over: np.ndarray | None = None) -> np.ndarray:
        """``from_model``: a state ``advance()`` returned. Its faults are not the caller's but the model's:
        ``model_error``. ``over``: the interval's times, named in an error (formatted only then: every request
        passes here)."""

        def refused(why: str) -> CosimError:
            where = "" if over is None else f" over t in [{over[0]:g}, {over[-1]:g}]"
            return CosimError("model_error" if from_model else "bad_value", f"{what}{where} {why}")

        if state is None:  # (it read "must have shape 1-D, got ()", blaming the parameters: a newcomer probe)
            raise refused("is None: a state is a 1-D array of floats (return it)")
        if type(state) is np.ndarray and state.dtype is _FLOAT64:  # (the common case, without a call)
            s = state
        elif getattr(getattr(state, "dtype", None), "kind", None) == "c":  # (a cast would drop the imaginary part)
            raise refused(f"is complex ({state.dtype}): a state is real numbers")
        else:
            try:
                s = np.asarray(state, dtype=np.float64)
            except (TypeError, ValueError):
                raise refused("is not a float vector") from None
        if s.ndim != 1 or (size is not None and s.size != size):
            want = f"({size},)" if size is not None else "1-D"
            raise refused(f"must have shape {want}, got {s.shape}")
        if not all_finite(s):
            raise refused("contains NaN or inf")
        return _readonly(s)

    def _input_function(
        self, times: np.ndarray, inputs: Mapping[str, Any], interp: str
    ) -> Callable[[float | np.ndarray], dict[str, np.ndarray]]:
        if type(inputs) is not dict and not isinstance(inputs, Mapping):  # (the common case without the ABC check)
            raise CosimError("bad_value", "inputs must be a map of input name -> samples")
        if inputs.keys() != self.inputs.keys():
            self._wrong_input_names(inputs)
        if not self.inputs:
            return lambda t: _Inputs()
        columns = []
        for name, port in self.inputs.items():
            v = inputs[name]
            if type(v) is not np.ndarray or v.dtype is not _FLOAT64:
                v = float_samples(name, v)
            if v.shape != (times.size, port.size):
                raise CosimError(
                    "bad_value", f"inputs.{name}: expected shape ({times.size}, {port.size}), got {v.shape}"
                )
            columns.append(v)
        values = columns[0] if len(columns) == 1 else np.concatenate(columns, axis=1)
        if not all_finite(values):  # one check for all inputs; name the first bad one
            bad = next(n for n, c in zip(self.inputs, columns) if not all_finite(c))
            raise CosimError("bad_value", f"inputs.{bad}: contains NaN or inf")
        at = interpolant(times, values, interp)  # times and values checked above
        if len(columns) == 1:
            (only,) = self.inputs
            return lambda t: _Inputs({only: at(t)})
        layout = self._input_layout
        if layout.ports is not self.inputs:  # (the ports configure made: a new dict each time)
            layout = self._input_layout = _InputLayout.of(self.inputs)
        items = layout.slices
        return lambda t: (lambda x: _Inputs({k: x[..., s] for k, s in items}))(at(t))

    def _wrong_input_names(self, inputs: Mapping[str, Any]) -> None:
        missing = [k for k in self.inputs if k not in inputs]
        unknown = [k for k in inputs if k not in self.inputs]
        parts = [f"missing {missing}" if missing else "", f"unknown {unknown}" if unknown else ""]
        known = ", ".join(f"{k}({p.size})" for k, p in self.inputs.items()) or "none"
        raise CosimError("bad_value", f"inputs: {'; '.join(p for p in parts if p)}; this subsim takes: {known}")

    def _wrong_output_names(self, outputs: Mapping[str, Any]) -> None:
        missing = [k for k in self.outputs if k not in outputs]
        unknown = [k for k in outputs if k not in self.outputs]
        if len(missing) == 1:  # (and the name it returned instead, a typo most likely: a newcomer probe)
            instead = f" (it returned {', '.join(map(repr, unknown))} instead)" if unknown else ""
            raise CosimError("model_error", f"advance() did not return output {missing[0]!r}{instead}")
        said = "did not return output(s) " + repr(missing) if missing else f"returned undeclared output(s) {unknown}"
        declared = ", ".join(f"{k}({p.size})" for k, p in self.outputs.items()) or "none"
        raise CosimError("model_error", f"advance() {said}; this subsim declares: {declared}")

    def _check_outputs(self, outputs: Mapping[str, Any], times: np.ndarray) -> dict[str, np.ndarray]:
        if type(outputs) is not dict and not isinstance(outputs, Mapping):  # (the common case without the ABC check)
            raise CosimError("model_error", f"advance() must return a map of outputs, got {type(outputs).__name__}")
        checked = {}
        if len(outputs) != len(self.outputs):
            self._wrong_output_names(outputs)
        for name, port in self.outputs.items():
            if name not in outputs:
                self._wrong_output_names(outputs)
            v = outputs[name]
            if getattr(getattr(v, "dtype", None), "kind", None) == "c":  # (a cast would drop the imaginary part)
                raise CosimError("model_error", f"advance() output {name!r} is complex ({v.dtype}): outputs are real")
            try:  # a copy: a model may hand back the same buffer every call, and a caller in this process keeps it
                v = np.array(v, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise CosimError("model_error", f"advance() output {name!r} is not an array of numbers "
                                 f"({type(exc).__name__}: {exc})") from None
            if v.ndim == 1 and port.size == 1:
                v = v.reshape(-1, 1)
            if v.shape != (times.size, port.size):
                want = (times.size, port.size)
                raise CosimError("model_error", f"advance() output {name!r} has shape {v.shape}, expected {want}")
            checked[name] = v
        together = np.concatenate(list(checked.values()), axis=1) if len(checked) > 1 else None
        if together is None or not all_finite(together):  # one check for all; then name the bad one
            for name, v in checked.items():
                if not all_finite(v):
                    i = int(np.argwhere(~np.isfinite(v))[0][0])
                    raise CosimError("model_error", f"output {name!r} is not finite at t = {float(times[i])!r}")
        return checked
