"""Subsystem physics: pure, vectorised functions in SI units, one module per subsystem.

:mod:`~l1b2.physics.params` (frozen parameter dataclasses loaded from the motor
files), :mod:`~l1b2.physics.driver` (Eq. 1-4), :mod:`~l1b2.physics.stator`
(Eq. 5-16), :mod:`~l1b2.physics.interface` (Eq. 17-20, 23),
:mod:`~l1b2.physics.slider` (Eq. 21-22) and :mod:`~l1b2.physics.steady` (the
coupled periodic steady state). Imports only :mod:`l1b2.errors` and :mod:`l1b2.units`.
"""
