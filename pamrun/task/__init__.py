"""The walking task: the Gymnasium env, its reward terms and gait clock, criteria, perturbations and symmetry."""
