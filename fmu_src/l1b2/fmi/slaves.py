"""The one slave template from which every FMU's pythonfmu script is generated.

PythonFMU's loader looks for a literal ``class Name(Fmi2Slave):`` in the
script (its 0.7.0 binary crashes on the second instantiation in a process
when the slave class inherits through an imported intermediate class), so
each FMU gets its own generated script; the logic lives in
:class:`l1b2.fmi.adapter.BlockAdapter` over a :mod:`l1b2.cosim.blocks` block.
"""

from __future__ import annotations

from typing import NamedTuple


class SlaveSpec(NamedTuple):
    block: str        #: block class in :mod:`l1b2.cosim.blocks` or :mod:`l1b2.cosim.composite`
    summary: str      #: one line: what the FMU is (the script's docstring)
    description: str  #: modelDescription ``description``


SLAVES: dict[str, SlaveSpec] = {
    'Driver': SlaveSpec(
        'DriverBlock',
        'Driver FMU: H-bridge inverter and LC resonance tank (paper Eq. 1-4).',
        'L1B2 USM driver: H-bridge fundamental (Eq. 1) through the LC resonance tank (exact phasor solution, Eq. 2-3) with drift of L and C1 (Eq. 4)'),
    'Interface': SlaveSpec(
        'InterfaceBlock',
        'Interface FMU: contact and stick-slip friction over one vibration period (paper Eq. 17-20, 23).',
        'L1B2 USM friction interface: intermittent contact (Eq. 17-18) and asperity stick-slip friction (Eq. 19-20) averaged over a vibration period; pure-slip mode as Eq. 23'),
    'L1B2Motor': SlaveSpec(
        'MotorBlock',
        'L1B2Motor FMU: the whole coupled motor (driver, stator, interface, slider) in one co-simulation FMU.',
        'L1B2 linear ultrasonic motor, four coupled subsystems (driver Eq. 1-4, stator Eq. 5-16, friction interface Eq. 17-20, slider Eq. 21-22) in one FMU, for hosts without SSP import'),
    'Predictor': SlaveSpec(
        'PredictorBlock',
        "Predictor FMU: the paper's Eq. 29 speed predictor with identified (or derived) parameters.",
        'L1B2 USM speed predictor (paper Eq. 29, parameters Eq. 35): inputs V0, position, load, direction; outputs the predicted speed and the closed-form steady speed'),
    'Slider': SlaveSpec(
        'SliderBlock',
        'Slider FMU: slider on its guide with stick, load and end stops (paper Eq. 21-22).',
        'L1B2 USM slider: m dv/dt + c_r v = F_d + F_g - F_load (Eq. 21) with Coulomb guide friction and stick (Eq. 22), signed pulley load and inelastic end stops'),
    'Stator': SlaveSpec(
        'StatorBlock',
        'Stator FMU: L1 and B2 modal envelopes with interface feedback (paper Eq. 5-16).',
        'L1B2 USM stator: L1 and B2 modal phasor envelopes (Eq. 6-7, steady state Eq. 12-13), axially loaded B2 mode shape (Eq. 9-11), preload P(s) (Eq. 16), interface feedback (Eq. 14)'),
}

TEMPLATE = '''"""{summary}"""
from pythonfmu import Fmi2Slave

from l1b2.cosim.{module} import {block}
from l1b2.fmi.adapter import BlockAdapter


class {name}(Fmi2Slave):
    author = {author!r}
    license = {license!r}
    description = {description!r}

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.adapter = BlockAdapter(self, {block})

    def exit_initialization_mode(self):
        self.adapter.exit_initialization_mode()

    def do_step(self, current_time, step_size):
        return self.adapter.do_step(current_time, step_size)

    def get_real(self, vrs):
        return self.adapter.get_real(vrs)

    def set_real(self, vrs, values):
        self.adapter.set_real(vrs, values)

    def get_integer(self, vrs):
        return self.adapter.get_other("Integer", vrs)

    def get_boolean(self, vrs):
        return self.adapter.get_other("Boolean", vrs)

    def get_string(self, vrs):
        return self.adapter.get_other("String", vrs)

    def set_integer(self, vrs, values):
        self.adapter.set_other("Integer", vrs, values)

    def set_boolean(self, vrs, values):
        self.adapter.set_other("Boolean", vrs, values)

    def set_string(self, vrs, values):
        self.adapter.set_other("String", vrs, values)

    def _get_fmu_state(self):
        return self.adapter.get_state(super()._get_fmu_state)

    def _set_fmu_state(self, state):
        self.adapter.set_state(state, super()._set_fmu_state)
'''


def slave_script(name: str, *, author: str, license: str) -> str:
    """Source of the pythonfmu script of FMU ``name`` (absolute ``l1b2`` imports, renamed when bundled)."""
    try:
        spec = SLAVES[name]
    except KeyError:
        raise ValueError(f"unknown FMU '{name}'; known: {', '.join(SLAVES)}") from None
    module = "composite" if spec.block in ("MotorBlock", "PredictorBlock") else "blocks"
    return TEMPLATE.format(name=name, module=module, block=spec.block, summary=spec.summary, description=spec.description,
                           author=author, license=license)
