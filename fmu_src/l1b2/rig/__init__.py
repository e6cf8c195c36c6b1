"""The virtual test rig: the paper's experiments on the co-simulated motor, with undeclared injections."""
