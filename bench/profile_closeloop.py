"""Profile one close loop of a blind case: ``SCRIPT KIND SEED [--out FILE]``.

``SCRIPT`` is ``blind_effects``, ``blind_effects_more`` or ``blind_effects_third`` (the module that makes the
case's data); the printed JSON row is that script's (:func:`blind_effects.loop_row`), the profile is taken with the
process CPU clock and written to ``--out`` (a ``pstats`` file), with the 25 heaviest entries by cumulative and by
own time printed to stderr."""
import argparse
import cProfile
import importlib
import io
import json
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_effects as be  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("script")
    ap.add_argument("kind")
    ap.add_argument("seed", type=int)
    ap.add_argument("--out", default="")
    ap.add_argument("--top", type=int, default=25)
    args = ap.parse_args(argv)
    mod = importlib.import_module(args.script)
    make = None if args.kind == "clean" else mod.experiment
    d = be.data_dir(args.kind, args.seed, Path(be.default_cache()), make)
    prof = cProfile.Profile(time.process_time)
    prof.enable()
    row, _ = be.loop_row(args.kind, args.seed, d)
    prof.disable()
    print(json.dumps(row))
    if args.out:
        prof.dump_stats(args.out)
    s = io.StringIO()
    st = pstats.Stats(prof, stream=s)
    st.sort_stats("cumulative").print_stats(args.top)
    st.sort_stats("tottime").print_stats(args.top)
    print(s.getvalue(), file=sys.stderr)


if __name__ == "__main__":
    main()
