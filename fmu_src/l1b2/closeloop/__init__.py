"""Close the loop with measured data: residual -> missing effect -> extended model -> error before and after.

:mod:`~l1b2.closeloop.residuals` (residual analysis: whiteness, position
spectrum, evidence per regressor by cross-validation over runs),
:mod:`~l1b2.closeloop.candidates` (the candidate library, an argument of the
estimator), :mod:`~l1b2.closeloop.selection` (exact scores against the fixed
baseline and the selection rules), :mod:`~l1b2.closeloop.loop` (the
:class:`~l1b2.closeloop.loop.CloseLoop` estimator and
:func:`~l1b2.closeloop.loop.close_loop`), :mod:`~l1b2.closeloop.settings` (their settings as one frozen record,
:class:`~l1b2.closeloop.settings.LoopSettings`), :mod:`~l1b2.closeloop.acceptance`
(cross-validated refits, :class:`~l1b2.closeloop.acceptance.RefitSettings`),
:mod:`~l1b2.closeloop.report` (the typed records of ``report.json``) and
:mod:`~l1b2.closeloop.result` (:class:`~l1b2.closeloop.result.CloseLoopResult`:
report, ``from_dict``, table, figures, ``save``). The effect families the
candidates come from live in :mod:`l1b2.predictor.effects`. No file is read
here; only ``CloseLoopResult.save`` writes; the export of a result is
composed in :func:`l1b2.workflows.export_close_loop`.
"""

from .candidates import CandidateLibrary, default_library, full_library
from .loop import CloseLoop, close_loop
from .result import CloseLoopResult

__all__ = ["CloseLoop", "close_loop", "CloseLoopResult", "CandidateLibrary", "default_library", "full_library"]
