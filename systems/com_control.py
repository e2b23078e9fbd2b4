"""COMControl: where the centre of mass ended up, for the characters the solver moved.

The paper's ``adaptRoot()`` runs inside the solver's loop, after the trunk in every iteration
(:func:`ecs_anim.runtime.kernels.solve_root.solve_root`, mirroring
:meth:`ecs_anim.solver.shell._Solve.root`: the root moves horizontally by the step that puts
the centre of mass back once the planted legs re-bend, or by the error times ``root_gain`` where
that is not predicted, lowered if a planted leg could not reach its footprint), so it is a step of
ConstraintSolve. This system checks its result every tick: the whole-body centre of mass (de Leva
segment masses of each body) of the solved posture and its horizontal distance from the desired
one, which metrics, tests and the viewer read. Switched off per character (``com_control``), the
error shows the drift the constraints cause.

Rows: characters with a Constraint component.
Reads: store.goals, solved (the solver's decoded result), com_desired, segment_mass_kg, segment_com_fraction.
Writes: store.com, store.com_error_m (NaN for characters nothing constrained this tick), in
place, by the compiled :mod:`ecs_anim.runtime.kernels.com`.
"""

from __future__ import annotations

import numpy as np

from ecs_anim.components import Constraint
from ecs_anim.core.morphology import centres_of_mass as numpy_centres
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.com import com_and_error_rows
from ecs_anim.runtime.system_base import System


class COMControl(System):
    query = (Constraint,)
    reads = ("goals", "solved", "com_desired", "segment_mass_kg", "segment_com_fraction")
    writes = ("com_error_m", "com")

    def run(self, dt: float) -> None:
        st = self.sim.store
        if st.com_error_m.shape == (st.n,) and st.com_error_m.flags.writeable:
            st.com_error_m.fill(np.nan)
        else:
            st.com_error_m = np.full(st.n, np.nan)
        if st.goals is None or st.solved is None:
            return
        rows = np.asarray(st.goals.rows, dtype=np.int64)  # type: ignore[attr-defined]
        if not self.sim.compiled:  # the kernels' numpy references, while they compile aside
            st.com[rows] = numpy_centres(st.solved.positions, st.segment_mass_kg[rows],
                                         st.segment_com_fraction[rows])
            st.com_error_m[rows] = np.linalg.norm(st.com[rows, :2] - st.com_desired[rows, :2],
                                                  axis=1)
            return
        over_chunks(com_and_error_rows, rows.size, rows, st.solved.positions, st.segment_mass_kg,
                    st.segment_com_fraction, st.com_desired, st.com, st.com_error_m)
