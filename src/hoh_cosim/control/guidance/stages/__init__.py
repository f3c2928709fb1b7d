"""The controller's stages, one feature each (`hoh_cosim.control.guidance.tick.Stage`): the law
(eq. 10 and the other fixed laws, or the variable law) and glide make the hand's request; the
release brake, the hold, the contact recovery, the passivity controller, the virtual fixture and
the follow make the command of it; the supervisor's limits come last in every mode."""
