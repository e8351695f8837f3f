"""Resolve ``"package.module:name"`` strings (models, transforms, unified references).

A scenario names the user's own modules: :func:`add_search_path` puts the scenario file's
directory and the working directory on the import path (at its end, so they never shadow an
installed package), and :data:`SEARCH_PATH` lists what was added. A scenario keeps its own two
directories, which ``cosim.launch`` hands to the subsim processes it starts (their ``PYTHONPATH``), and
which decide between two scenarios' modules of the same name in one interpreter (:func:`import_object`).
"""

from __future__ import annotations

import ast
import hashlib
import importlib
import importlib.machinery
import importlib.util
import os
import sys
import sysconfig
import traceback
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from cosim.subsim import Subsim

SEARCH_PATH: list[str] = []  # directories add_search_path put on sys.path, in order
MODULE_PATH_ENV = "COSIM_MODULE_PATH"  # a launched subsim's scenario directories (os.pathsep-separated)


def add_search_path(*directories: str | Path) -> None:
    """Append each directory (made absolute) to ``sys.path`` and :data:`SEARCH_PATH`, once."""
    for d in directories:
        path = os.path.abspath(d)
        if path not in SEARCH_PATH:
            SEARCH_PATH.append(path)
        if path not in sys.path:
            sys.path.append(path)
            importlib.invalidate_caches()


def import_object(path: str, what: str, search_path: Sequence[str] = ()) -> Any:
    """The object ``name`` of ``package.module``; ValueError naming ``what`` and the path otherwise.

    ``search_path``: the directories of the scenario that names it. A module of another scenario's
    directories with the same name, imported earlier in this interpreter or found first on ``sys.path``,
    is then replaced by this scenario's (a study over model variants, each in its own directory)."""
    module_name, sep, attr = str(path).partition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"{what} {path!r} must be 'package.module:name'")
    try:
        _take_own(module_name.partition(".")[0], search_path)
        module = importlib.import_module(module_name)
    except ImportError as exc:
        missing = exc.name if isinstance(exc, ModuleNotFoundError) else None
        if missing and (module_name == missing or module_name.startswith(missing + ".")):  # the module itself
            raise ValueError(f"{what} {path!r} not found ({exc})") from None
        # the module was found; an import in it failed (it said "not found" of a file that is there: a newcomer)
        raise ValueError(f"{what} {path!r}: importing {module_name!r} raised {_where(exc)}") from None
    except Exception as exc:  # the module itself is broken (a syntax error, a NameError at import): say where
        raise ValueError(f"{what} {path!r}: importing {module_name!r} raised {_where(exc)}") from None
    try:
        return getattr(module, attr)
    except AttributeError as exc:
        raise ValueError(f"{what} {path!r} not found ({exc}){_shadowed(module, search_path)}") from None


def _shadowed(module: Any, search_path: Sequence[str]) -> str:
    """A hint when the module imported is an installed or standard one while a file of that name sits in the
    scenario's directories (``code.py`` beside the scenario: Python's own ``code`` was imported)."""
    top = module.__name__.partition(".")[0]
    found = [os.path.join(d, top + ".py") for d in search_path if os.path.isfile(os.path.join(d, top + ".py"))]
    mine = getattr(module, "__file__", None)
    if not found or (mine is not None and os.path.abspath(mine) in map(os.path.abspath, found)):
        return ""
    return (f": {top!r} is {mine or 'built into Python'}, which comes before {found[0]} (installed modules go first):"
            f" rename {os.path.basename(found[0])}")


def _home(spec: importlib.machinery.ModuleSpec | None) -> str | None:
    """The directory a top-level module or package was found in (None: built in, frozen, namespace)."""
    if spec is None or not spec.has_location or spec.origin is None:
        return None
    origin = os.path.dirname(spec.origin)
    return os.path.dirname(origin) if spec.submodule_search_locations is not None else origin


def _take_own(top: str, search_path: Sequence[str]) -> None:
    """Import ``top`` as ``search_path``, in its order, finds it, if what Python would use instead is another
    scenario-directory module of that name (from a directory in :data:`SEARCH_PATH`: another scenario's, or this
    one's working directory where its own directory has one). Installed modules are never touched."""
    if not search_path:
        return
    loaded = sys.modules.get(top)
    current = getattr(loaded, "__spec__", None) if loaded is not None else importlib.util.find_spec(top)
    if _home(current) not in SEARCH_PATH:  # installed, built in, or nowhere
        return
    spec = importlib.machinery.PathFinder.find_spec(top, list(search_path))
    if spec is None or spec.loader is None or spec.origin == current.origin:  # none here, or the same file
        return
    for name in [k for k in sys.modules if k == top or k.startswith(top + ".")]:
        del sys.modules[name]
    module = importlib.util.module_from_spec(spec)
    sys.modules[top] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[top]
        raise


def use_search_path(directories: Sequence[str]) -> None:
    """In a subsim process ``cosim run`` started: import from its scenario's ``directories`` as the coordinator
    does, after the installed packages and in their order (``python -m`` put the working directory first, where
    a module of the working directory would shadow one beside the scenario)."""
    gone = {os.path.abspath(d) for d in directories} | {os.getcwd()}
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") not in gone]
    add_search_path(*directories)
    importlib.invalidate_caches()


_LIBRARIES = tuple({p for k in ("stdlib", "purelib", "platlib") if (p := sysconfig.get_paths().get(k))}) + (
    os.path.dirname(os.path.abspath(__file__)) + os.sep,)  # (cosim itself: an editable install is in neither)


def own_frame(exc: BaseException, skip: int = 1) -> traceback.FrameSummary | None:
    """The innermost frame of ``exc``'s traceback, past its ``skip`` outermost (the catcher's own), that is a user's
    code: outside the standard library, installed packages (NumPy's fromnumeric.py) and cosim; None if none is."""
    for frame in reversed(traceback.extract_tb(exc.__traceback__)[skip:]):
        if frame.filename and not frame.filename.startswith(_LIBRARIES) and not frame.filename.startswith("<"):
            return frame
    return None


def _where(exc: Exception) -> str:
    """``Type: message`` of an exception raised while importing a user's module, with the file and line it
    came from (a SyntaxError names them in its message already)."""
    if isinstance(exc, SyntaxError):
        return f"{type(exc).__name__}: {exc}"
    frames = traceback.extract_tb(exc.__traceback__)
    last = own_frame(exc, skip=0) or (frames[-1] if frames else None)  # (an import fails in importlib's frames)
    return f"{type(exc).__name__}: {exc}" + (f" ({last.filename}, line {last.lineno})" if last else "")


def load_model(path: str, search_path: Sequence[str] = ()) -> type[Subsim]:
    """The :class:`cosim.Subsim` subclass at ``package.module:Class``; ValueError naming the path otherwise.
    ``search_path``: as for :func:`import_object`."""
    if ":" not in str(path):  # e.g. the package name ``spawn_subsim`` or ``python -m`` takes
        found = _models_in(str(path))
        hint = f" (did you mean {' or '.join(repr(f) for f in found)}?)" if found else ""
        raise ValueError(f"model {path!r} must be 'package.module:Class'{hint}")
    cls = import_object(path, "model", search_path)
    if not (isinstance(cls, type) and issubclass(cls, Subsim)):
        raise ValueError(f"model {path!r} is not a cosim.Subsim subclass")
    return cls


def _models_in(module_name: str) -> list[str]:
    """``module:Class`` of the classes a module, or its package's ``subsim`` module, defines on a base whose name
    ends in ``Subsim`` (``Subsim``, ``ParamsSubsim``), read from their source (for a hint: nothing is run)."""
    found = []
    for name in (module_name, f"{module_name}.subsim"):
        try:
            spec = importlib.util.find_spec(name)  # (for a dotted name, Python imports its parent package)
            if spec is None or spec.origin is None or not spec.origin.endswith(".py"):
                continue
            tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
        except (Exception, SystemExit):
            continue
        found += [f"{name}:{node.name}" for node in tree.body if isinstance(node, ast.ClassDef)
                  and any(str(getattr(b, "id", getattr(b, "attr", ""))).endswith("Subsim") for b in node.bases)]
        if spec.submodule_search_locations is None:  # a module, not a package: no subsim module in it
            break
    return found


def code_digests(module: str) -> dict[str, str]:
    """The model code this process runs, as ``{module name: the first 16 hex digits of the SHA-256 of its file}``
    (line ends as LF: a Windows checkout is the same code): every module loaded here from the top-level package of
    ``module`` (or ``module`` alone), and from the directory that holds it, the model's project (a helper module
    beside it, ``rk4.py``), unless that is where libraries are installed; cosim's own modules are not the model's.
    A subsim's ``describe`` says it (``code``), and a coordinator compares it with its own files
    (:func:`differing_code`): a subsim moved to another machine with an older copy of its package ran there without
    a word."""
    top = module.partition(".")[0]
    if top == "__main__":  # a script's name, not its file: another process's __main__ is another script
        return {}
    project = _project(getattr(sys.modules.get(top), "__file__", None))
    found = {}
    for name, loaded in list(sys.modules.items()):
        path = getattr(loaded, "__file__", None)
        ours = name == top or name.startswith(top + ".")
        if not ours and (project is None or not isinstance(path, str) or not path.startswith(project)
                         or _module_file(project, name) != os.path.abspath(path)):
            continue  # (a module loaded from there under another name could not be found by its name elsewhere)
        digest = _file_digest(path)
        if digest is not None:
            found[name] = digest
    return found


def _project(top_file: str | None) -> str | None:
    """The directory (ending in a separator) holding a top-level package (its ``__init__.py``) or module, unless
    libraries are installed there."""
    if not top_file:
        return None
    path = os.path.abspath(top_file)
    base = os.path.dirname(os.path.dirname(path) if os.path.basename(path) == "__init__.py" else path) + os.sep
    return None if base.startswith(_LIBRARIES) else base


def _module_file(project: str, name: str) -> str | None:
    """Where module ``name`` is under ``project`` (a module file or a package's ``__init__.py``), if it is there and
    is no library's (cosim's own, a virtualenv inside the project)."""
    parts = name.split(".")
    if not all(part.isidentifier() for part in parts):
        return None
    for path in (os.path.join(project, *parts) + ".py", os.path.join(project, *parts, "__init__.py")):
        if os.path.isfile(path):
            return None if path.startswith(_LIBRARIES) else path
    return None


def _file_digest(path: str | None) -> str | None:
    if not path or not path.endswith(".py"):
        return None
    try:
        return hashlib.sha256(Path(path).read_bytes().replace(b"\r\n", b"\n")).hexdigest()[:16]
    except OSError:
        return None


def differing_code(code: Mapping[str, str], model: str) -> list[str]:
    """The modules of ``code`` (another process's :func:`code_digests`) whose file on this machine differs: those of
    the top-level package of ``model`` (``package.module[:Class]``) and of the directory that holds it here (its
    project, as :func:`code_digests` takes it). Files are looked up by name where that package is found on this
    machine's import path, nothing imported; modules not found there are not compared (the names come from the
    other process)."""
    top = model.partition(":")[0].partition(".")[0]
    try:
        spec = importlib.util.find_spec(top) if top and top != "__main__" else None  # (a top-level name: no import)
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.has_location or not spec.origin:
        return []
    project = _project(spec.origin)
    roots = list(spec.submodule_search_locations or [])  # a package's directories; none for a lone module
    differ = []
    for name, digest in sorted(code.items()):
        if name == top:
            path = spec.origin
        elif name.startswith(top + ".") and roots:
            parts = name.split(".")[1:]
            if not all(part.isidentifier() for part in parts):
                continue
            path = next((str(p) for root in roots for p in (Path(root, *parts).with_suffix(".py"),
                                                              Path(root, *parts, "__init__.py")) if p.is_file()), None)
        elif project is not None:
            path = _module_file(project, name)
        else:
            continue
        mine = _file_digest(path)
        if mine is not None and mine != digest:
            differ.append(name)
    return differ
