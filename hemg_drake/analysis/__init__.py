"""Analysis of logged runs: metrics, contact and stability, below the visualisation."""
