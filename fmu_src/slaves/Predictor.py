"""Predictor FMU: the paper's Eq. 29 speed predictor with identified (or derived) parameters."""
from pythonfmu import Fmi2Slave

from l1b2.blocks import PredictorBlock
from l1b2.fmi_base import BlockAdapter


class Predictor(Fmi2Slave):
    author = "L1B2 USM tool team"
    license = "MIT"
    description = ("L1B2 USM speed predictor (paper Eq. 29, parameters Eq. 35): inputs V0, position, load, "
                   "direction; outputs the predicted speed and the closed-form steady speed")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.adapter = BlockAdapter(self, PredictorBlock)

    def exit_initialization_mode(self):
        self.adapter.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self.adapter.do_step(current_time, step_size)

    def _set_fmu_state(self, state):
        super()._set_fmu_state(state)
        self.adapter.after_state_restore()
