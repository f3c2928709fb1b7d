"""Emulated devices for rehearsals and for other people's clients: the world, the FT-150 server, the
FSE103 pseudo-terminal, the UR controller (dashboard, RTDE, script port), and `hw rehearse`'s logic.

    world.py          the rehearsal world in a process of its own, the FT-150 server, the FSE103 pty
    ur_controller.py  a loopback UR controller over the world's arm
    rtde_protocol.py  RTDE's packages, as the emulated controller speaks them
    rehearse.py       one session of the real runner against all of it
"""
