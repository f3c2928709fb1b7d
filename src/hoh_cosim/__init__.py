"""hoh-cosim: hand-over-hand control of a robot-held ultrasound probe.

Importing the package stays light: heavy or optional parts (FMI, hardware drivers, plotting) are
imported where they are used.
"""

__version__ = "0.1.0"
