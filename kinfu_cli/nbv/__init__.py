"""Next-best-view: candidate viewpoints, ray casting through the ternary map, gains."""
