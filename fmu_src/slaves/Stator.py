"""Stator FMU: L1 and B2 modal envelopes with interface feedback (paper Eq. 5-16)."""
from pythonfmu import Fmi2Slave

from l1b2.blocks import StatorBlock
from l1b2.fmi_base import BlockAdapter


class Stator(Fmi2Slave):
    author = "L1B2 USM tool team"
    license = "MIT"
    description = ("L1B2 USM stator: L1 and B2 modal phasor envelopes (Eq. 6-7, steady state Eq. 12-13), "
                   "axially loaded B2 mode shape (Eq. 9-11), preload P(s) (Eq. 16), interface feedback (Eq. 14)")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.adapter = BlockAdapter(self, StatorBlock)

    def exit_initialization_mode(self):
        self.adapter.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self.adapter.do_step(current_time, step_size)

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self.adapter.after_state_restore()
