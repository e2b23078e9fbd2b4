"""``ecs-anim batch``: clips x bodies x grounds on local cores or a Ray cluster
(:mod:`.jobs`), and its HTML report (:mod:`.report`)."""
