"""Body appearance descriptors of a person crop (colour and texture histograms), pure numpy/OpenCV."""
