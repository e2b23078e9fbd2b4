"""Data-only ECS components (installed as ``ecs_anim.components``)."""
