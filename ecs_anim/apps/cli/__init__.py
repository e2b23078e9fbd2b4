"""The ``ecs-anim`` command line: :func:`ecs_anim.apps.cli.main.main` (the console script)."""
