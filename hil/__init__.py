"""Hardware-in-the-loop checks of the firmware against the Python evaluation."""
