"""enkf package."""
