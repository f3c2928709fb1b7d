"""The hardware runner: drivers for the UR5, the FT-150 stream and the FSE103, and the loop."""
