"""ECS systems, one esper processor per file (installed as ``ecs_anim.systems``)."""
