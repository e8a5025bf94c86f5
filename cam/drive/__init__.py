"""Driving the machine: ports, the runner, the machine session, the grbl and MAXIMUS hosts.

This is the only part of `cam` that sleeps or writes to hardware.  What to
send is planned below it (:mod:`cam.motion`: the step plan and its speed
ramps; :mod:`cam.pins`: the pin map).  Import from the modules:
:mod:`cam.drive.ports` (ports opened by name), :mod:`cam.drive.runner`,
:mod:`cam.drive.session`, :mod:`cam.drive.maximus`.
"""
