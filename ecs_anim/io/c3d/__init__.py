"""C3D in: labelled markers straight to joint centres (:mod:`.importing`, the pipeline, over
:mod:`.reading`, :mod:`.label_roles`, :mod:`.repair`, :mod:`.joint_centres` and the modules it
names, :mod:`.gait_events`, :mod:`.lab_centres` and :mod:`.absent_fill`), marker-set presets
(:mod:`.marker_sets`) and the lab's force plates (:mod:`.force_plates`)."""

from ecs_anim.io.c3d.importing import import_c3d

__all__ = ["import_c3d"]
