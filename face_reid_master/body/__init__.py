"""Body appearance evidence in the master: metrics learned from person pairs and their re-id evaluation."""
