"""Robot models: the Baxter right arm as a MultibodyPlant."""
