"""What a process needs to host our PythonFMU-based FMUs safely (Linux).

The FMUs' binaries are PythonFMU 0.7.0's ``libpythonfmu-export`` (renamed to
the model identifier). Two facts about them shape every host:

1. **libpython is not linked.** The binary has undefined ``Py*`` symbols and
   no ``DT_NEEDED`` entry for libpython, so its ``dlopen`` fails with
   ``undefined symbol: PyExc_...`` unless a ``libpython3.11.so`` is already
   loaded with ``RTLD_GLOBAL``. Python hosts (fmpy, libcosimpy) have it;
   any other host must load it first: ``dlopen(libpython, RTLD_NOW |
   RTLD_GLOBAL)`` in its own code (see ``l1b2/fmi/chost/fmu_host.c``) or
   ``LD_PRELOAD=<libpython>`` in the environment. :func:`l1b2.fmi.runtime.libpython_path`
   finds the library of the running interpreter. The embedded interpreter
   then finds its standard library from libpython's compiled-in prefix;
   ``PYTHONPATH`` must name a ``site-packages`` with numpy and scipy
   (:func:`l1b2.fmi.runtime.host_environment`), and ``PYTHONHOME`` must not point at a
   virtual environment (a venv has no standard library).

2. **Exit-time use-after-free.** The binary keeps a static
   ``std::shared_ptr<PyState>``. At ``exit()`` its C++ static destructor runs
   first, then the library destructor ``onLibraryUnload()`` assigns
   ``nullptr`` to the already destroyed pointer and releases the control
   block a second time. In a C host that let the FMU start Python this
   aborts the process (``free(): corrupted ...`` / SIGSEGV) after all results
   are written; in Python hosts it is an invalid read (valgrind) that may
   or may not crash. ``dlclose`` does not help: the library has
   ``STB_GNU_UNIQUE`` symbols and is never unloaded. The fix is to call the
   library's exported ``finalizePythonInterpreter()`` once all instances are
   freed and before ``exit``: it empties the pointer while it is alive, so
   both destructors find nothing to release. In a Python host this does
   *not* finalize the interpreter (PythonFMU only finalizes an interpreter it
   started itself).

Two fixes, one inside the FMUs and one for Python hosts:

* :func:`register_exit_fix_in_fmu` runs inside every FMU when it is
  instantiated (``l1b2.fmi.adapter.BlockAdapter``): it registers the library's
  own ``finalizePythonInterpreter`` with the C runtime's ``__cxa_atexit``.
  Exit handlers run in reverse order of registration and the library's static
  destructor was registered when the library was loaded, i.e. earlier, so at
  ``exit()`` the pointer is emptied first. This makes *any* host safe
  (OpenModelica, Dymola, Simulink, fmpy, libcosim, a C host that does
  nothing special): measured with ``chost/fmu_host.c -x plain``, the
  Interface and Predictor FMUs aborted at exit in 20 of 20 runs without it
  and in 0 of 20 with it; valgrind reports no invalid access.
* :func:`install_exit_fix` registers :func:`finalize_pythonfmu_libraries` with
  :mod:`atexit` for Python hosts (``l1b2.cosim.master`` installs it before it loads
  an FMU; call it yourself when you load our FMUs with fmpy or libcosimpy
  directly). It also covers FMUs built before the in-FMU fix and other
  PythonFMU FMUs in the same process.

Calling ``finalizePythonInterpreter`` more than once is harmless (the second
call finds the pointer empty).
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
from pathlib import Path

#: the FMU binaries of a PythonFMU FMU, as they appear in ``/proc/self/maps``
_BINARY_DIR = "/binaries/linux64/"
_installed = False
_registered_in_fmu: set[str] = set()



# ---------------------------------------------------------------------------
# Exit fix (Python hosts)
# ---------------------------------------------------------------------------

def loaded_fmu_libraries() -> list[str]:
    """Paths of the FMU shared libraries mapped into this process (Linux ``/proc/self/maps``)."""
    libs: list[str] = []
    try:
        with open("/proc/self/maps") as fh:
            for line in fh:
                parts = line.split(maxsplit=5)
                if len(parts) == 6 and _BINARY_DIR in parts[5]:
                    path = parts[5].strip()
                    if path.endswith(" (deleted)"):
                        path = path[: -len(" (deleted)")]
                    if path.endswith(".so") and path not in libs:
                        libs.append(path)
    except OSError:  # not Linux: nothing to do
        pass
    return libs


def finalize_pythonfmu_libraries() -> list[str]:
    """Call ``finalizePythonInterpreter()`` in every loaded PythonFMU library; return their paths.

    Only when no instance of those FMUs will be used any more (it is meant
    for process exit). Libraries without that symbol (other FMUs) are left
    alone. A library is reached with ``RTLD_NOLOAD``, so nothing new is
    loaded, and deleted files (extraction folders already removed) still
    resolve to the mapped library by name.
    """
    done = []
    for path in loaded_fmu_libraries():
        try:
            lib = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        except OSError:
            continue
        fn = getattr(lib, "finalizePythonInterpreter", None)
        if fn is None:
            continue
        fn.restype = None
        fn.argtypes = []
        fn()
        done.append(path)
    return done


def install_exit_fix() -> bool:
    """Register :func:`finalize_pythonfmu_libraries` to run at interpreter exit (once per process).

    Returns True when it was installed by this call. Registered handlers run
    in reverse order, so this one (installed when FMUs are about to be
    loaded) runs before cleanup registered earlier, e.g. the removal of
    extraction folders by :mod:`l1b2.cosim.master`.
    """
    global _installed
    if _installed or not sys.platform.startswith("linux"):
        return False
    atexit.register(finalize_pythonfmu_libraries)
    _installed = True
    return True


def register_exit_fix_in_fmu(resources: str | os.PathLike | None, model_identifier: str) -> bool:
    """From inside an FMU: have ``exit()`` call this FMU library's ``finalizePythonInterpreter`` first.

    ``resources`` is the FMU's resources folder (``Fmi2Slave.resources``); the
    library is ``../binaries/linux64/<model_identifier>.so`` beside it, reached
    with ``RTLD_NOLOAD`` (the host has loaded it). Registered once per library
    and process with ``__cxa_atexit`` (no DSO handle: the library is never
    unloaded, it has ``STB_GNU_UNIQUE`` symbols). Returns True when it
    registered; never raises (Linux only, otherwise a no-op).
    """
    try:
        if not sys.platform.startswith("linux") or not resources:
            return False
        so = Path(resources).resolve().parent / "binaries" / "linux64" / f"{model_identifier}.so"
        key = str(so)
        if key in _registered_in_fmu or not so.exists():
            return False
        lib = ctypes.CDLL(key, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        fn = getattr(lib, "finalizePythonInterpreter", None)
        if fn is None:
            return False
        libc = ctypes.CDLL(None)
        cxa_atexit = libc.__cxa_atexit
        cxa_atexit.restype = ctypes.c_int
        cxa_atexit.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        if cxa_atexit(ctypes.cast(fn, ctypes.c_void_p), None, None) != 0:
            return False
        _registered_in_fmu.add(key)
        return True
    except Exception:  # noqa: BLE001 - runs inside an FMI callback: never let an exception out
        return False
