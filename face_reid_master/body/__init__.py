"""The body metric the master embeds body descriptors with (its file and the features it fuses); it is learned
offline by :mod:`face_reid_master.training.body`."""
