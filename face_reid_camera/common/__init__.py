"""Code both packages use (the master imports the camera package only from here and from its face and body
models): checks, parameter tables, embedding spaces, sealing, stamps, model files; ``common.ros`` for the nodes."""
