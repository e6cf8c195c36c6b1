"""Slider FMU: slider on its guide with stick, load and end stops (paper Eq. 21-22)."""
from l1b2.blocks import SliderBlock
from l1b2.fmi_base import BlockSlave


class Slider(BlockSlave):
    BLOCK = SliderBlock
    SECTION = "slider"
    description = ("L1B2 USM slider: m dv/dt + c_r v = F_d + F_g - F_load (Eq. 21) with Coulomb guide "
                   "friction and stick (Eq. 22), signed pulley load and inelastic end stops")
