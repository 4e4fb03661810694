"""Calibration of a camera network (pure algorithms; the tools call them)."""
