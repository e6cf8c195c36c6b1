"""Optional compilation of the per-step physics kernels with numba (issue: faster than real time).

The hot kernels (:func:`l1b2.physics.interface.interface_forces_scalar` and
what it calls) are written in plain Python restricted to floats, ``math`` and
tuples, so that numba can compile the *same source*. :func:`compile_family`
compiles such a family of functions; the plain functions stay untouched (they
are the pure-Python kernel, used when numba is missing or disabled, and the
"old kernel" of ``bench/bench_kernel.py``).

Kernels compiled this way: the interface's period averages
(:func:`l1b2.physics.interface.period_integrals`), the stator's envelope step
(:func:`l1b2.physics.stator.coupled_envelope_step`), the slider's event loop
(:func:`l1b2.physics.slider.step_floats`), and the whole coupled step that
calls them all (:func:`l1b2.physics.coupled.motor_substeps`, used by
``L1B2Motor.fmu``). They are used when

* numba is importable (it is a project dependency, installed by ``make``), and
* the environment variable ``L1B2_JIT`` is not ``0`` (``L1B2_JIT=0`` forces
  the pure-Python kernels, e.g. for a host interpreter without numba; blocks
  read it when they are initialised).

Otherwise, or if compilation fails, the pure-Python functions are used and
:func:`jit_status` says why.

Caching across FMU extractions
------------------------------
numba caches compiled code next to the source file, or under
``NUMBA_CACHE_DIR`` in a folder named after the *source path*. Every FMU of
ours bundles this package and every host extracts an FMU into a fresh
temporary folder, so a path-keyed cache would compile again (seconds) for
every FMU instance. The locator installed here keys the cache by the module's
name and the SHA-256 of the sources of every module its family spans
(:func:`family_digest`; numba itself checks only the entry's file) instead, in ``$L1B2_CACHE_DIR/numba``
(default ``~/.cache/l1b2/numba``): every extraction of one FMU (its bundle has a
fixed package name per FMU and version) loads the kernel compiled by the
first. The name is part of the key because a cached kernel refers to its
module by name. When that folder is not writable numba's own locators are used.
"""

from __future__ import annotations

import hashlib
import os
import types
from pathlib import Path

#: why the compiled kernels are or are not used ("compiled", or the reason for the fallback)
_STATUS = {"state": "not requested"}


def jit_enabled() -> bool:
    """True unless ``L1B2_JIT=0`` (or ``false``/``no``/``off``) is set in the environment."""
    return os.environ.get("L1B2_JIT", "1").strip().lower() not in ("0", "false", "no", "off")


def jit_status() -> str:
    """``"disabled by L1B2_JIT=0"``, or how the last :func:`compile_family` call ended: ``"compiled"`` or why
    it fell back to Python (``"not requested"`` before any)."""
    return "disabled by L1B2_JIT=0" if not jit_enabled() else _STATUS["state"]


def cache_root() -> Path:
    """Folder of the content-keyed numba cache: ``$L1B2_CACHE_DIR/numba``, else ``~/.cache/l1b2/numba``."""
    base = os.environ.get("L1B2_CACHE_DIR")
    if base:
        return Path(base) / "numba"
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "l1b2" / "numba"


def _install_locator(numba_caching):
    """Put the content-keyed locator first in numba's list of cache locators (once per process); returns it.

    Every copy of this module (each FMU bundles one) finds the locator the
    first copy installed and registers its files there.
    """
    impl = getattr(numba_caching, "CacheImpl", None) or getattr(numba_caching, "_CacheImpl")
    base = getattr(numba_caching, "_CacheLocator")
    mixin = getattr(numba_caching, "_SourceFileBackedLocatorMixin")
    for cls in impl._locator_classes:
        if getattr(cls, "L1B2_CONTENT_KEYED", 0) == 2:
            return cls

    class ContentCacheLocator(mixin, base):
        """Cache folder named after the module and the content hash of its family's source files."""

        L1B2_CONTENT_KEYED = 2  # version of the registration protocol (``registered`` maps path -> digest)
        registered: dict = {}   # entry source file (absolute path) -> digest of its family's sources

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            # the module name is part of the key: a cached kernel refers to its module by name
            digest = self.registered[os.path.abspath(py_file)]
            self._cache_path = str(cache_root() / f"{py_func.__module__}-{digest}")

        def get_cache_path(self):
            return self._cache_path

        @classmethod
        def from_function(cls, py_func, py_file):
            if os.path.abspath(py_file) not in cls.registered:
                return None
            return super().from_function(py_func, py_file)

    impl._locator_classes.insert(0, ContentCacheLocator)
    return ContentCacheLocator


def family_digest(functions: dict) -> str:
    """SHA-256 (20 hex digits) of the source files of ``functions``: the key of their compiled code.

    numba's cache checks only the entry's own file; a kernel that inlines
    helpers from other modules must be compiled again when any of them changes.
    """
    h = hashlib.sha256()
    for path in sorted({os.path.abspath(f.__code__.co_filename) for f in functions.values()}):
        h.update(Path(path).read_bytes())
    return h.hexdigest()[:20]


def compile_family(functions: dict, entry: str, signature: str):
    """Compile ``functions`` (name -> plain function, of one or several modules) with numba; the compiled
    ``entry``.

    The functions are cloned with namespaces (a copy of each one's module
    globals) in which every name of the family refers to its compiled clone,
    so that the compiled entry calls compiled helpers while the modules' own
    functions stay pure Python. Only the entry is cached on disk, keyed by the
    content of every source file of the family (:func:`family_digest`); the
    cached entry holds its helpers' code. ``signature`` (numba's string form)
    makes the entry compile (or load from the cache) at once, so a failure
    shows here and not mid-simulation.

    Returns ``None`` when numba is missing, disabled by ``L1B2_JIT=0``, or
    fails; :func:`jit_status` then says why.
    """
    if not jit_enabled():
        _STATUS["state"] = "disabled by L1B2_JIT=0"
        return None
    try:
        import numba
        from numba.core import caching
    except Exception as exc:  # pragma: no cover - numba is a dependency; a foreign host may lack it
        _STATUS["state"] = f"numba not importable ({type(exc).__name__}: {exc})"
        return None
    try:
        locator = _install_locator(caching)
        locator.registered[os.path.abspath(functions[entry].__code__.co_filename)] = family_digest(functions)
        namespaces: dict[int, dict] = {}  # one per module of the family
        clones = {}
        for name, f in functions.items():
            ns = namespaces.setdefault(id(f.__globals__), dict(f.__globals__))
            clones[name] = types.FunctionType(f.__code__, ns, name, f.__defaults__, f.__closure__)
            clones[name].__qualname__ = f.__qualname__
            clones[name].__module__ = f.__module__
        for name, clone in clones.items():
            if name != entry:
                compiled = numba.njit(clone)
                for ns in namespaces.values():
                    ns[name] = compiled
        compiled = numba.njit(signature, cache=True)(clones[entry])
        for ns in namespaces.values():
            ns[entry] = compiled
    except Exception as exc:
        _STATUS["state"] = f"compilation failed ({type(exc).__name__}: {exc})"
        return None
    _STATUS["state"] = "compiled"
    return compiled


def cached_kernel(slot: list, family):
    """The compiled kernel of ``family()``, compiled at the first call and kept in ``slot`` (a module's list).

    ``family`` returns ``(functions, entry, signature)`` for :func:`compile_family`;
    it is called only to compile. ``None`` while ``L1B2_JIT=0`` is set (checked
    at every call, so a host can switch between the compiled and the Python
    kernels between simulations) or when compilation is not possible
    (:func:`jit_status`).
    """
    if not jit_enabled():
        return None
    if not slot:
        slot.append(compile_family(*family()))
    return slot[0]
