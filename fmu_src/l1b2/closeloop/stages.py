"""Time and evaluations per stage of a close-loop job (what ``report.json``'s ``stages`` holds)."""

from __future__ import annotations

import time

__all__ = ["StageClock"]


class StageClock:
    """A progress callback that also times the stages it announces.

    Calling the clock with a message closes the stage running (if any) and
    opens one named by the message, then passes the message on to ``say``.
    :meth:`count` adds identifications and their function evaluations to the
    open stage (a fold refit returns its evaluations with its errors, also
    from a Dask worker; a coarse-to-fine identification counts both stages'
    evaluations, the coarse ones on fewer samples).
    :meth:`close` ends the last stage and returns the records, in order:
    ``{"stage", "wall_s", "cpu_s", "identifications", "nfev"}``, ``cpu_s``
    being this process' CPU time (workers' not included).
    """

    def __init__(self, say):
        self.say = say
        self.records: list[dict] = []
        self._open: dict | None = None

    def __call__(self, message: str) -> None:
        self._close()
        self._open = {"stage": str(message), "t0": time.perf_counter(), "c0": time.process_time(),
                      "identifications": 0, "nfev": 0}
        self.say(message)

    def count(self, identifications: int = 0, nfev: int = 0) -> None:
        """Add ``identifications`` fits and ``nfev`` evaluations to the open stage."""
        if self._open is not None:
            self._open["identifications"] += int(identifications)
            self._open["nfev"] += int(nfev)

    def _close(self) -> None:
        rec, self._open = self._open, None
        if rec is not None:
            self.records.append({"stage": rec["stage"], "wall_s": round(time.perf_counter() - rec["t0"], 3),
                                 "cpu_s": round(time.process_time() - rec["c0"], 3),
                                 "identifications": rec["identifications"], "nfev": rec["nfev"]})

    def close(self) -> list[dict]:
        """End the open stage; the records of every stage."""
        self._close()
        return list(self.records)
