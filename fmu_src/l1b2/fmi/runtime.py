"""What a non-Python host needs to load our PythonFMU-based FMUs (Linux): libpython, environment, a C host.

See :mod:`l1b2.cosim.hosting` for the two facts about PythonFMU 0.7.0
binaries that shape every host (libpython not linked; the exit-time
use-after-free and its fix).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

CHOST_DIR = Path(__file__).resolve().parent / "chost"
CHOST_SOURCE = CHOST_DIR / "fmu_host.c"


# ---------------------------------------------------------------------------
# What a non-Python host needs
# ---------------------------------------------------------------------------

def libpython_path() -> Path:
    """The shared libpython of the running interpreter (the one the FMUs' code was tested with).

    Raises :class:`FileNotFoundError` for an interpreter built without
    ``--enable-shared`` (no libpython to load: use another Python build).
    """
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    names = [sysconfig.get_config_var("LDLIBRARY") or "", sysconfig.get_config_var("INSTSONAME") or "",
             f"libpython{sys.version_info.major}.{sys.version_info.minor}.so"]
    for name in names:
        if name.endswith(".so") or ".so." in name:
            p = Path(libdir) / name
            if p.exists():
                return p
    raise FileNotFoundError(f"no shared libpython in {libdir!r} (this Python is not built with --enable-shared)")


def site_packages() -> list[str]:
    """The ``site-packages`` folders of the running environment (numpy, scipy for the embedded interpreter)."""
    import site
    paths = list(site.getsitepackages()) if hasattr(site, "getsitepackages") else []
    purelib = sysconfig.get_paths()["purelib"]
    if purelib not in paths:
        paths.insert(0, purelib)
    return [p for p in paths if Path(p).is_dir()]


def host_environment(base: dict | None = None) -> dict[str, str]:
    """Environment for a non-Python host process: ``PYTHONPATH`` = our site-packages, no ``PYTHONHOME``.

    Also sets ``L1B2_LIBPYTHON`` (read by ``chost/fmu_host.c``) and
    ``OPENBLAS_NUM_THREADS=1`` unless already set.
    """
    env = dict(os.environ if base is None else base)
    env.pop("PYTHONHOME", None)
    extra = os.pathsep.join(site_packages())
    env["PYTHONPATH"] = extra + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.setdefault("L1B2_LIBPYTHON", str(libpython_path()))
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    return env


def fmi2_headers() -> Path:
    """Folder of the FMI 2.0 C headers that fmpy ships (``fmi2Functions.h`` ...)."""
    import fmpy
    path = Path(fmpy.__file__).resolve().parent / "c-code"
    if not (path / "fmi2Functions.h").exists():
        raise FileNotFoundError(f"fmpy has no FMI 2 headers in {path}")
    return path


def compile_c_host(dest: str | Path, cc: str | None = None) -> Path:
    """Compile ``chost/fmu_host.c`` into the executable ``dest`` (gcc/cc, FMI 2 headers from fmpy)."""
    cc = cc or shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        raise FileNotFoundError("no C compiler (gcc or cc) on PATH")
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    cmd = [cc, "-O2", "-Wall", "-Wextra", "-std=c99", f"-I{fmi2_headers()}", "-o", str(dest), str(CHOST_SOURCE),
           "-ldl"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the C host failed: {' '.join(cmd)}\n{proc.stderr}")
    return dest
