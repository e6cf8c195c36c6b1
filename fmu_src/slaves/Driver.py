"""Driver FMU: H-bridge inverter and LC resonance tank (paper Eq. 1-4)."""
from pythonfmu import Fmi2Slave

from l1b2.blocks import DriverBlock
from l1b2.fmi_base import BlockAdapter


class Driver(Fmi2Slave):
    author = "L1B2 USM tool team"
    license = "MIT"
    description = ("L1B2 USM driver: H-bridge fundamental (Eq. 1) through the LC resonance tank "
                   "(exact phasor solution, Eq. 2-3) with drift of L and C1 (Eq. 4)")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.adapter = BlockAdapter(self, DriverBlock)

    def exit_initialization_mode(self):
        self.adapter.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self.adapter.do_step(current_time, step_size)

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self.adapter.after_state_restore()
