"""shpb package."""
