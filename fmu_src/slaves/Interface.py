"""Interface FMU: contact and stick-slip friction over one vibration period (paper Eq. 17-20, 23)."""
from pythonfmu import Fmi2Slave

from l1b2.blocks import InterfaceBlock
from l1b2.fmi_base import BlockAdapter


class Interface(Fmi2Slave):
    author = "L1B2 USM tool team"
    license = "MIT"
    description = ("L1B2 USM friction interface: intermittent contact (Eq. 17-18) and asperity stick-slip "
                   "friction (Eq. 19-20) averaged over a vibration period; pure-slip mode as Eq. 23")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.adapter = BlockAdapter(self, InterfaceBlock)

    def exit_initialization_mode(self):
        self.adapter.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self.adapter.do_step(current_time, step_size)

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self.adapter.after_state_restore()
