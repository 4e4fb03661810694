"""Offline training: what the fitting tools and the simulator learn from data (never imported by the nodes)."""
