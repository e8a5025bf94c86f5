"""Step plans: a job's moves become the machine's writes (issue #48 point 4: the job -> step plan stage).

Pure computation, no port and no clock: :mod:`cam.motion.chunks` plans any
job a chunk of periods at a time (:func:`~cam.motion.chunks.plan_chunks`),
:mod:`cam.motion.steps` joins the chunks into one
:class:`~cam.motion.steps.StepPlan` and documents the signals,
:mod:`cam.motion.ramps` lengthens the periods with the speed ramps, and
:mod:`cam.motion.kernels` holds their compiled loops.  :mod:`cam.drive`
sends the plans.
"""
