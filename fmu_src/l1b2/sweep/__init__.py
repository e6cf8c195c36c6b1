"""Design studies: operating-point maps and Monte-Carlo sweeps of the co-simulated motor on Dask."""
