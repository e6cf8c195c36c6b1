"""Native (C) co-simulation FMUs, FMI 2.0 and 3.0, with the variables of the Python FMUs (:mod:`.build`)."""
