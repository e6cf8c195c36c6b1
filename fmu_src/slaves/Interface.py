"""Interface FMU: contact and stick-slip friction over one vibration period (paper Eq. 17-20, 23)."""
from l1b2.blocks import InterfaceBlock
from l1b2.fmi_base import BlockSlave


class Interface(BlockSlave):
    BLOCK = InterfaceBlock
    SECTION = "interface"
    description = ("L1B2 USM friction interface: intermittent contact (Eq. 17-18) and asperity stick-slip "
                   "friction (Eq. 19-20) averaged over a vibration period; pure-slip mode as Eq. 23")
