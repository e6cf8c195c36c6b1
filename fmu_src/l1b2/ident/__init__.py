"""Maximum-likelihood identification of the Eq. 29 predictor from measured data (Eq. 32, 35)."""
