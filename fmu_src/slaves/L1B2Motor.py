"""L1B2Motor FMU: the whole coupled motor (driver, stator, interface, slider) in one co-simulation FMU."""
from pythonfmu import Fmi2Slave

from l1b2.blocks import MotorBlock
from l1b2.fmi_base import BlockAdapter


class L1B2Motor(Fmi2Slave):
    author = "L1B2 USM tool team"
    license = "MIT"
    description = ("L1B2 linear ultrasonic motor, four coupled subsystems (driver Eq. 1-4, stator Eq. 5-16, "
                   "friction interface Eq. 17-20, slider Eq. 21-22) in one FMU, for hosts without SSP import")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.adapter = BlockAdapter(self, MotorBlock)

    def exit_initialization_mode(self):
        self.adapter.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self.adapter.do_step(current_time, step_size)

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self.adapter.after_state_restore()
