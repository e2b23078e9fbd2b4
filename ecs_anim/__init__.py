"""ecs_anim: morphology-independent motion for many characters."""
