"""Driver FMU: H-bridge inverter and LC resonance tank (paper Eq. 1-4)."""
from l1b2.blocks import DriverBlock
from l1b2.fmi_base import BlockSlave


class Driver(BlockSlave):
    BLOCK = DriverBlock
    SECTION = "driver"
    description = ("L1B2 USM driver: H-bridge fundamental (Eq. 1) through the LC resonance tank "
                   "(exact phasor solution, Eq. 2-3) with drift of L and C1 (Eq. 4)")
