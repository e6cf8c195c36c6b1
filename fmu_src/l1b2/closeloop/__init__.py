"""Close the loop with measured data: residuals, candidate library, selection, the loop and its result."""
