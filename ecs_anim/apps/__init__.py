"""The applications on top: the ``ecs-anim`` command line (:mod:`.cli`), batches of clips x
bodies x grounds (:mod:`.batch`), the benchmark (:mod:`.bench`) and the pyglet viewer
(:mod:`.viewer`)."""
