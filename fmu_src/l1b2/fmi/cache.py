"""FMUs built on demand into a per-user cache, keyed by package version and content.

Commands that need the subsystem FMUs and are not given a folder call
:func:`ensure_fmus`: the first call builds them (a few seconds each) into
``$XDG_CACHE_HOME/l1b2/fmus/<version>-<key>/`` (``~/.cache`` by default;
``L1B2_CACHE_DIR`` overrides the root) and later calls reuse them. The key
hashes everything an FMU is made of: the bundled runtime sources, the motor
parameter set, and the pythonfmu version, so an edited package or motor
never reuses a stale FMU.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from dataclasses import asdict
from pathlib import Path

from .. import __version__
from ..physics.params import MotorParams, load_motor
from .build import GUARD_SOURCE, SUBSYSTEM_FMUS, build_fmu, runtime_files


def cache_root() -> Path:
    """Root of the per-user FMU cache."""
    if os.environ.get("L1B2_CACHE_DIR"):
        return Path(os.environ["L1B2_CACHE_DIR"]) / "fmus"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "l1b2" / "fmus"


def cache_key(mp: MotorParams, names=SUBSYSTEM_FMUS) -> str:
    """Version and content hash of the FMUs ``names`` built for motor ``mp``."""
    import pythonfmu
    h = hashlib.sha256()
    for f in runtime_files() + [GUARD_SOURCE]:  # the guard library is compiled into every FMU
        h.update(f.name.encode())
        h.update(f.read_bytes())
    h.update(json.dumps(asdict(mp), sort_keys=True, default=str).encode())
    h.update(f"pythonfmu {pythonfmu.__version__}|{','.join(names)}".encode())
    return f"{__version__}-{h.hexdigest()[:16]}"


def ensure_fmus(mp: MotorParams | None = None, names=SUBSYSTEM_FMUS, *, log=print) -> Path:
    """Folder with the FMUs ``names`` for motor ``mp`` (default: reference), building them once if needed.

    The build goes into a temporary sibling folder that is renamed into place
    when complete, so an interrupted build never leaves a partial cache entry
    and two processes building at once both end with a complete folder.
    """
    mp = mp or load_motor()
    root = cache_root()
    final = root / cache_key(mp, names)
    if all((final / f"{n}.fmu").is_file() for n in names):
        return final
    root.mkdir(parents=True, exist_ok=True)
    if log is not None:
        log(f"building the FMUs {', '.join(names)} once into the cache {final}")
    tmp = Path(tempfile.mkdtemp(prefix=".build-", dir=root))
    try:
        for n in names:
            build_fmu(n, tmp, mp=mp)
        try:
            tmp.rename(final)
        except OSError:  # another process finished first: keep its complete folder
            if not all((final / f"{n}.fmu").is_file() for n in names):
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return final
