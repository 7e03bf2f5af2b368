"""The benchmark suite for crane control methods (thesis §5.2): ``kvp crane-bench``.

Operational profiles (:mod:`.profiles`, TOML files) say how the crane is used; the suite runs
every run of a profile against any solver of the universal architecture
(:mod:`pyopenshowvar.universal`) on a crane plant of its own — MuJoCo rigid-body dynamics
driven by a hydraulic model (:mod:`.plant`, :mod:`.hydraulics`) — and measures the thesis'
direct metrics (position and joint error, composed cost, joint effort; :mod:`.metrics`) and
its indirect one, the heave-compensation test on a moving ship (:mod:`.bench`).
See docs/maritime.md, "The crane benchmark suite".
"""
