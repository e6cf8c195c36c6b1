"""Co-simulation: blocks over the physics, the in-process engine, the SSP system structure and the fmpy master.

:mod:`~l1b2.cosim.blocks` (the subsystems as stateful step objects, also the
FMUs' runtime), :mod:`~l1b2.cosim.engine` (the blocks wired by hand, no FMUs),
:mod:`~l1b2.cosim.ssp` (SSD/SSV/SSP reading and writing) and
:mod:`~l1b2.cosim.master` (the SSD-driven fmpy master).
"""
