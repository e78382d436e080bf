"""Points of interest from a hand trajectory: GMM-AS and the ZVC baseline, run per task by attention.detect."""
