"""Maritime case studies: a motion-compensated crane head and an underwater GA planner.

* :mod:`.delta`, :mod:`.crane`, :mod:`.cranehead`: the three-axis compensator (TAC), a Delta
  parallel robot at the tip of a ship crane (Henriksen, Røine, Skjong & Johansen, "Three-axis
  Motion Compensated Crane Head Control"), simulated on a supply vessel in irregular seas;
  ``kvp crane-head``.
* :mod:`.vessel`, :mod:`.imu`: a supply vessel's 6-DOF wave-frequency motion from a sea
  spectrum and the motion sensor the controllers read, reusable by any compensation study.
* :mod:`.underwater`: GA path and posture planning for a 7-DOF underwater manipulator
  (Ishibashi, Shimizu & Ito, "The motion planning for underwater manipulators depend on
  genetic algorithm"); ``kvp underwater-plan``.

See docs/maritime.md for the models, their sources and our figures beside the papers'.
"""
