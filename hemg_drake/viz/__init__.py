"""Visualisation: Meshcat recordings to HTML replays, and the paper's figures."""
