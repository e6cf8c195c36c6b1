"""L1B2 linear ultrasonic motor: physics, FMU co-simulation and identification.

Subsystem physics (pure, vectorised, SI units) lives in one module per
subsystem: :mod:`l1b2.physics.driver`, :mod:`l1b2.physics.stator`, :mod:`l1b2.physics.interface`,
:mod:`l1b2.physics.slider`. Parameters are frozen dataclasses loaded from
``system_models/`` by :mod:`l1b2.physics.params`.
"""

__version__ = "0.1.0"
