"""Stator FMU: L1 and B2 modal envelopes with interface feedback (paper Eq. 5-16)."""
from l1b2.blocks import StatorBlock
from l1b2.fmi_base import BlockSlave


class Stator(BlockSlave):
    BLOCK = StatorBlock
    SECTION = "stator"
    description = ("L1B2 USM stator: L1 and B2 modal phasor envelopes (Eq. 6-7, steady state Eq. 12-13), "
                   "axially loaded B2 mode shape (Eq. 9-11), preload P(s) (Eq. 16), interface feedback (Eq. 14)")
