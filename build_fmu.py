#!/usr/bin/env python
"""Build the project's FMUs into dist/fmus/ (``python build_fmu.py [--out DIR] [NAME ...]``).

The work is done by :mod:`l1b2.fmi.build`: the physics package is bundled
under a version-unique name, pythonfmu is vendored, and modelDescription.xml
gets units, ranges, model structure and metadata.
"""
import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "fmu_src"))

from l1b2.fmi.build import SUBSYSTEM_FMUS, build_fmu  # noqa: E402
from l1b2.fmi.slaves import SLAVES  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=list(SUBSYSTEM_FMUS),
                    help=f"FMUs to build, of {', '.join(SLAVES)} (default: the four subsystems)")
    ap.add_argument("--out", type=Path, default=Path("dist/fmus"), help="destination folder")
    args = ap.parse_args(argv)
    for name in args.names:
        print(build_fmu(name, args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
