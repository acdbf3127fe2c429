"""The simulator: a physically based plenoptic 2.0 camera array with ground truth."""
