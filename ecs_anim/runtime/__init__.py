"""The real-time layer: the :class:`~ecs_anim.runtime.simulation.Simulation` (one esper world,
the schedule, the structure-of-arrays store), events and triggers, steering, body changes,
metrics and the compiled kernels of the tick (:mod:`.kernels`). Its public API is re-exported
by :mod:`ecs_anim`."""
