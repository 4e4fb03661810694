"""Body-metric learning from person crops (XQDA, KISSME, model selection, CMC) for face-reid-fit-body."""
