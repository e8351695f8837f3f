"""Resume points of a run on disk: ``<results>.resume.npz`` (:func:`~cosim.outputs.resume_path`), so that an
interrupted run goes on where it was.

Every checkpoint (each ``[run] checkpoint_every`` intervals) the coordinator has every subsim's committed state and
the coupler's :class:`~cosim.coupler.relaxation.ResumePoint`. Once the results are written up to that point, the
runner saves both here, atomically; ``cosim run --resume`` restores the subsims to them, cuts the results back to
that point and goes on, with the same results as a run that was never interrupted. A run that ends normally
removes the file.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cosim.coupler.relaxation import ResumePoint
from cosim.handles import SubsimState
from cosim.outputs import OutputError, atomic_write

FORMAT = "cosim resume point"
IRRELEVANT = {"stop", "run", "description"}  # a run may be resumed to go further, with other restarts or timeouts


def fingerprint(raw: Mapping[str, Any], method: str) -> str:
    """What must not change between a run and its resumption: the scenario's tables (but for IRRELEVANT ones)
    and the method."""
    tables = _numbers_as_floats({k: v for k, v in raw.items() if k not in IRRELEVANT})
    text = json.dumps([tables, method], sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


def fingerprinted(raw: Mapping[str, Any], method: str) -> dict[str, Any]:
    """What :func:`fingerprint` hashes, as JSON has it: saved with a resume point to say what changed since."""
    tables = _numbers_as_floats({k: v for k, v in raw.items() if k not in IRRELEVANT})
    return json.loads(json.dumps({**tables, "method": method}, sort_keys=True, default=repr))


_ABSENT = object()  # a key one of the two scenarios does not have


def changes(old: Any, new: Any, where: str = "") -> list[str]:
    """The keys whose values differ between two fingerprinted scenarios, ``key: old -> new`` (a list's items by
    index while it keeps its length)."""
    if isinstance(old, dict) and isinstance(new, dict):
        return [c for k in sorted(old.keys() | new.keys(), key=str)
                for c in changes(old.get(k, _ABSENT), new.get(k, _ABSENT), f"{where}.{k}" if where else k)]
    if isinstance(old, list) and isinstance(new, list):
        if len(old) == len(new):
            return [c for i, (a, b) in enumerate(zip(old, new)) for c in changes(a, b, f"{where}[{i}]")]
        before, after = [_text(x) for x in old], [_text(x) for x in new]
        kept_before, kept_after = set(before), set(after)
        gone = [_shown(x, t) for x, t in zip(old, before) if t not in kept_after]  # (a coupling added or removed)
        came = [_shown(x, t) for x, t in zip(new, after) if t not in kept_before]
        return [f"{where}: {len(old)} -> {len(new)} items" + "".join(
            f"; {what} {', '.join(items[:3])}{', ...' if len(items) > 3 else ''}"
            for what, items in (("removed", gone), ("added", came)) if items)]
    a, b = _text(old), _text(new)  # (as the fingerprint sees them: -0.0 is not 0.0)
    return [] if a == b else [f"{where}: {_shown(old, a)} -> {_shown(new, b)}"]


def _text(v: Any) -> str:
    return "(absent)" if v is _ABSENT else json.dumps(v, sort_keys=True, ensure_ascii=False)


def _shown(v: Any, text: str) -> str:
    """A value as a line shows it: a whole number without '.0', at most 60 characters."""
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15 and text != "-0.0":
        text = str(int(v))
    return text if len(text) <= 60 else text[:28] + "..." + text[-29:]


def _numbers_as_floats(v: Any) -> Any:
    """``u0 = 0`` and ``u0 = 0.0`` are the same scenario."""
    if isinstance(v, Mapping):
        return {k: _numbers_as_floats(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_numbers_as_floats(x) for x in v]
    return float(v) if isinstance(v, int) and not isinstance(v, bool) else v


@dataclass(frozen=True)
class Saved:
    """A resume point as saved: whose run it is (``fingerprint``, the run's start), the coupler's point, and every
    subsim's committed state there."""

    fingerprint: str
    t_start: float
    point: ResumePoint
    states: dict[str, SubsimState]
    written: Mapping[str, Any] | None = None  # the results files' bytes and SHA-256 up to the point (ResultWriter)
    models: Mapping[str, str] | None = None  # SHA-256 of each file the subsims' parameters name (an FMU), by path
    scenario: Mapping[str, Any] | None = None  # what was fingerprinted (:func:`fingerprinted`), to say what changed
    code: Mapping[str, Mapping[str, str]] | None = None  # each subsim's model code (Description.code), by subsim


def save(path: Path, saved: Saved) -> None:
    """Write ``saved`` to ``path`` atomically (readers see the previous point or this one whole)."""
    arrays: dict[str, np.ndarray] = {}
    for name, st in saved.states.items():
        arrays[f"state/{name}"] = st.state
    for key, (t, v) in saved.point.previous.items():
        arrays[f"previous_t/{key}"], arrays[f"previous/{key}"] = t, v
    for key, m in saved.point.magnitudes.items():
        arrays[f"magnitude/{key}"] = m
    meta = {"format": FORMAT, "fingerprint": saved.fingerprint, "t_start": saved.t_start, "t": saved.point.t,
            "length": saved.point.length, "patience": saved.point.patience,
            "ceiling": None if math.isinf(saved.point.ceiling) else saved.point.ceiling,
            "subsims": {name: {"time": st.time, "model": st.model} for name, st in saved.states.items()},
            "written": saved.written, "models": saved.models, "scenario": saved.scenario, "code": saved.code}
    meta["digest"] = _digest(meta, arrays)
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)

    def write(f: io.BufferedIOBase) -> None:
        np.savez(f, **arrays)

    atomic_write(path, write)


def load(path: Path) -> Saved:
    """The resume point in ``path``; OutputError in one line when there is none or it is not one."""
    if not path.is_file():
        raise OutputError(f"no resume point {path}: the run stopped before its first checkpoint, or ended (a "
                          "finished run removes it); run it again from the start (--overwrite instead of "
                          "--resume)")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(bytes(z["meta"]).decode())
            if meta.get("format") != FORMAT:
                raise ValueError("not a resume point")
            states = {name: SubsimState(float(s["time"]), z[f"state/{name}"], s["model"])
                      for name, s in meta["subsims"].items()}
            previous = {k.removeprefix("previous/"): (z[f"previous_t/{k.removeprefix('previous/')}"], z[k])
                        for k in z.files if k.startswith("previous/")}
            magnitudes = {k.removeprefix("magnitude/"): z[k] for k in z.files if k.startswith("magnitude/")}
            digest = meta.pop("digest", None)  # (absent from points saved before it was kept)
            edited = digest is not None and digest != _digest(meta, {k: z[k] for k in z.files if k != "meta"})
    except Exception as exc:  # whatever a cut or damaged file makes zipfile or numpy raise
        why = " ".join(str(exc).split())[:120]
        raise OutputError(f"{path} is damaged or not a resume point ({type(exc).__name__}: {why}): run it again "
                          "from the start with --overwrite") from None
    if edited:  # a state or a coupler's signal changed by hand or on disk: the results would differ without a word
        raise OutputError(f"{path} is not as its run saved it (its contents do not match the SHA-256 saved with them: "
                          "edited or damaged since): run it again from the start with --overwrite")
    ceiling = meta.get("ceiling")  # (absent from points saved before it was kept)
    point = ResumePoint(float(meta["t"]), meta["length"], previous, magnitudes,
                        math.inf if ceiling is None else float(ceiling), int(meta.get("patience", 0)))
    return Saved(meta["fingerprint"], float(meta["t_start"]), point, states, meta.get("written"), meta.get("models"),
                 meta.get("scenario"), meta.get("code"))


def _digest(meta: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> str:
    """SHA-256 of a resume point's contents: its metadata (but the digest) and every array, by name."""
    h = hashlib.sha256(json.dumps({k: v for k, v in meta.items() if k != "digest"}, sort_keys=True).encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"\0{name}\0{a.dtype.str}\0{a.shape}\0".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def changed_code(saved: Mapping[str, Mapping[str, str]], now: Mapping[str, Mapping[str, str]]) -> dict[str, list[str]]:
    """By subsim, the modules of its model code (``Description.code``) whose file is another now than at the resume
    point (modules loaded then and now: what else a process loads is no change of the model)."""
    out = {}
    for name, before in saved.items():
        after = now.get(name, {})
        differ = sorted(m for m in before.keys() & after.keys() if before[m] != after[m])
        if differ:
            out[name] = differ
    return out


def model_files(params: Mapping[str, Mapping[str, Any]]) -> dict[str, str]:
    """SHA-256 of each file on this machine that a subsim's parameter names (an FMU, a table), by its path: a resume
    with other files goes on, and says so (fixing a model is a reason to resume)."""
    out = {}
    for p in params.values():
        for value in p.values():
            if not isinstance(value, str) or not value:
                continue
            try:  # any text may be a parameter's: a long one, a NUL in it
                if Path(value).is_file():
                    with open(value, "rb") as f:
                        out[value] = hashlib.file_digest(f, "sha256").hexdigest()
            except (OSError, ValueError):
                continue
    return out
