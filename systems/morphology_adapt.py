"""MorphologyAdapt: the normalized poses on each character's own body (paper §6, eq. 2).

Reads: store.poses, store.lengths (a body replaced while playing takes effect the next tick).
Writes: store.scaled (joint positions and part frames on each body, before ground adaptation),
in place when the store's arrays still fit (compiled :func:`ecs_anim.kernels.decode.decode`).
"""

from __future__ import annotations

from ecs_anim.kernels.decode import decode, fits
from ecs_anim.system_base import System


class MorphologyAdapt(System):
    def run(self, dt: float) -> None:
        st = self.sim.store
        reuse = st.scaled if fits(st.scaled, st.n) else None
        st.scaled = decode(st.poses, st.lengths, reuse)
