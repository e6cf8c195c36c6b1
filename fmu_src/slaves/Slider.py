"""Slider FMU: slider on its guide with stick, load and end stops (paper Eq. 21-22)."""
from pythonfmu import Fmi2Slave

from l1b2.blocks import SliderBlock
from l1b2.fmi_base import BlockAdapter


class Slider(Fmi2Slave):
    author = "L1B2 USM tool team"
    license = "MIT"
    description = ("L1B2 USM slider: m dv/dt + c_r v = F_d + F_g - F_load (Eq. 21) with Coulomb guide "
                   "friction and stick (Eq. 22), signed pulley load and inelastic end stops")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.adapter = BlockAdapter(self, SliderBlock)

    def exit_initialization_mode(self):
        self.adapter.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self.adapter.do_step(current_time, step_size)

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self.adapter.after_state_restore()
