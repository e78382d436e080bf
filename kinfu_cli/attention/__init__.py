"""Points of interest from a hand trajectory: GMM-AS and the ZVC baseline."""
