"""``session_blocks``: contiguous blocks of the session's runs, each block its own run-level effect.

A rig session is often recorded in blocks that nothing logged describes: files, batches, shifts, a drive re-tuned
or a fixture re-seated between two series. The runs of one block then share a deviation from the model, and the
next block has another. No logged channel follows such levels and no smooth function of the session clock does
(they are drawn anew at each block). This family gives each block its own run-level effect.

The blocks are contiguous in the session: with edges ``e_1 < ... < e_(B-1)`` [s] on the session clock, block ``j``
(``j = 0 ... B - 1``) holds the runs whose mean session time lies in ``[e_j, e_(j+1))`` (``e_0 = -inf``,
``e_B = +inf``; :func:`block_index`). Its columns are the blocks' centred indicators ``x_j = 1[run in block j] -
s_j`` (``s_j`` the share of TRAIN's runs in block ``j``; the last block dropped, :func:`block_columns`), each
scaling the drive force, ``dF = a_j x_j V0/V_ref``: ``B - 1`` parameters ``a_j`` [N], one per block but the last,
against TRAIN's average over runs. One parameter per block, not the run-level family's three (a gain, an offset and
a load term): a block of a few runs, some of them held out by a fold, identifies one level, and over the plan's
voltages ``V0/V_ref`` changes by a few tens of per cent, so the drive's scale also carries most of a friction
level's change. A run before the first edge or after the last belongs to the first or the last block.

Where the edges come from: the close loop's run-level analysis (:mod:`l1b2.closeloop.blocks`) searches them on the
runs' own deviations from the current model and offers :meth:`SessionBlocks.hypotheses` of a significant
segmentation. The family reads the session clock's run mean (``run:time_s``) only to place each run in its block:
a block's level is estimated from TRAIN runs within it, which is how a TEST run interleaved in the same block is
predicted; the refit acceptance cross-validates it over runs (:attr:`SessionBlocks.run_folds`), not over blocks of
the session, which would hold out whole blocks whose levels no other run carries. ``Predictor.fmu`` has no input
for the session clock, so the family is not exportable (:func:`l1b2.predictor.effects.channels.export_problem`),
like every effect of the session clock: the blocks are a fact of the recorded session, not of the motor. Its
columns average to zero over TRAIN's runs, so the calibrated model leaves it out and predicts the session's average
(:attr:`SessionBlocks.session_average`, :func:`l1b2.closeloop.calibrated.calibrated_model`).
"""

from __future__ import annotations

import numpy as np

from .base import V_REF, Effect, EffectSpecError, num, register, signal
from .channels import SESSION_TIME, signal_key

#: the run-level transform name of a segmentation's signal in the close loop's run-level analysis
BLOCKS = "blocks"


def blocks_spec(edges_s, shares) -> dict:
    """A segmentation's scalars in a spec: ``n_blocks``, ``edge_1..edge_{B-1}`` [s], ``share_0..share_{B-2}``."""
    edges, shares = [float(e) for e in edges_s], [float(s) for s in shares]
    if len(shares) != len(edges) or not edges or np.any(np.diff(edges) <= 0):
        raise EffectSpecError(f"session blocks: {len(edges)} increasing edges and as many shares needed, got "
                              f"edges {edges} and shares {shares}")
    out = {"channel": SESSION_TIME, "n_blocks": len(edges) + 1}
    out.update({f"edge_{j + 1}": e for j, e in enumerate(edges)})
    out.update({f"share_{j}": s for j, s in enumerate(shares)})
    return out


def blocks_of(spec) -> tuple[tuple, tuple]:
    """``(edges [s], shares)`` of a spec (:func:`blocks_spec`)."""
    n = int(num(spec, "n_blocks"))
    if n < 2:
        raise EffectSpecError(f"session blocks: {n} blocks")
    return tuple(num(spec, f"edge_{j}") for j in range(1, n)), tuple(num(spec, f"share_{j}") for j in range(n - 1))


def block_index(t_s, edges_s) -> np.ndarray:
    """Each value's block, ``0 ... len(edges)``: the number of edges at or below its session time [s]."""
    return np.searchsorted(np.asarray(edges_s, float), np.asarray(t_s, float), side="right")


def index_columns(idx, shares) -> np.ndarray:
    """The centred block indicators ``(n, B - 1)`` of block indices ``idx``: ``1[block j] - s_j`` for every block
    but the last (``shares``: the ``B - 1`` shares ``s_j``)."""
    s = np.asarray(shares, float)
    return (np.asarray(idx)[:, None] == np.arange(len(s))[None, :]).astype(float) - s[None, :]


def block_columns(t_s, edges_s, shares) -> np.ndarray:
    """The centred block indicators ``(n, B - 1)`` of session times [s] (:func:`block_index`, :func:`index_columns`)."""
    return index_columns(block_index(t_s, edges_s), shares)


@register
class SessionBlocks(Effect):
    """``session_blocks``: contiguous blocks of the session's runs, each its own run-level effect (module docstring).

    Not listed by any candidate library: the close loop's run-level analysis offers :meth:`hypotheses` of a
    significant segmentation (report family ``session_blocks(<B>)``).
    """

    kind = "session_blocks"
    regressor = "session_block"
    group = "run_level"
    description = ("contiguous blocks of the session's runs (files, batches, shifts), each scaling the drive force "
                   "(constant along the stroke)")
    #: cross-validated over runs, not over blocks of the session (module docstring)
    run_folds = True
    #: ``Predictor.fmu`` has no input for the session clock (module docstring)
    exportable = False
    #: a fact of the recorded session whose columns average to zero over TRAIN's runs: the calibrated model leaves it
    #: out and predicts the session's average (:func:`l1b2.closeloop.calibrated.calibrated_model`)
    session_average = True

    @staticmethod
    def label(n_blocks: int) -> str:
        """The report's name of a segmentation's signal, ``session_blocks(<B>)``."""
        return f"session_blocks({int(n_blocks)})"

    def needs(self, spec):
        return super().needs(spec) | {signal_key(SESSION_TIME, "run")}

    def features(self, spec, x):
        """Per block ``j`` but the last, ``x_j V0/V_ref``, ``x_j`` its centred indicator of the run's mean session
        time (:func:`block_columns`)."""
        edges, shares = blocks_of(spec)
        X = block_columns(signal(x, signal_key(SESSION_TIME, "run")), edges, shares)
        return X * (signal(x, "V0") / V_REF)[:, None]

    def width(self, spec):
        return int(num(spec, "n_blocks")) - 1

    def channel_mean(self, spec):
        return None

    def hypotheses(self, segmentations: list) -> list:
        """One hypothesis per segmentation ``{"edges", "shares"}``: one parameter per block but the last,
        ``block_<j>_run_gain`` [N]."""
        out = []
        for sg in segmentations:
            spec = blocks_spec(sg["edges"], sg["shares"])
            n = spec["n_blocks"]
            label = self.label(n)
            out.append(self.hypothesis(
                [f"block_{j}_run_gain" for j in range(n - 1)], ["N"] * (n - 1), spec, "run", family=label,
                generic=True, description=f"{label}: {n} contiguous blocks of the session's runs, edges at "
                + ", ".join(f"{e:.1f}" for e in sg["edges"]) + " s, each scaling the drive force (against the runs' "
                "average)"))
        return out

    def grid(self, train):
        """The hypothesis of every segmentation ``train``'s session clock record holds (``block_edges`` and
        ``block_shares``, what :mod:`l1b2.closeloop.blocks` finds). The loop does not list these: its run-level
        analysis offers :meth:`hypotheses` of a significant segmentation."""
        return self.hypotheses([{"edges": ch["block_edges"], "shares": ch["block_shares"]} for ch in train.channels
                                if ch.get("name") == SESSION_TIME and "block_edges" in ch and "block_shares" in ch])
