"""Files in and out: BVH (:mod:`.bvh`, :mod:`.importing`), C3D (:mod:`.c3d`), joint maps,
foot-contact detection, exports (:mod:`.export`: BVH, glTF, npz) and the project's own motion
library (:mod:`.library`). Public entry points are re-exported by :mod:`ecs_anim`."""
