"""Body appearance of a person seen by the camera: colour and texture histograms of the body's parts."""
