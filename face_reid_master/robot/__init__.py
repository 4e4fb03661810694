"""Robot-facing cores: goals to named people, the camera network's floor map and its alignment to a robot's map."""
