"""Studies built from many runs: the scenario x controller x horizon suite and the paper-claims
report."""
