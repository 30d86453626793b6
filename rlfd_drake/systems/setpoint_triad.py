"""SetpointTriad: draws a pose signal (e.g. the controller's set-point) as a Meshcat
triad that follows it during a simulation and in Meshcat recordings."""

from __future__ import annotations

import math

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import Context, EventStatus, LeafSystem

from rlfd_drake.view import AddTriad, SetTriadPose, TriadStyle, pose_vector_to_rigid_transform

__all__ = ["SetpointTriad"]


class SetpointTriad(LeafSystem):
    """Moves a Meshcat triad to the pose on its input, at a fixed period.

    .. pydrake_system::

        name: SetpointTriad
        input_ports:
        - X_WE

    * ``X_WE`` (7): the pose to draw, ``[p_WE (3) m, q_WE (4) wxyz]`` (world frame;
      the quaternion is normalised before drawing).

    The triad (:func:`rlfd_drake.view.AddTriad`) is created at ``path`` when the system
    is constructed. A publish event at initialisation and every ``period_s`` calls
    ``meshcat.SetTransform(path, X_WE, t)``, so that while Meshcat is recording
    (``StartRecording``) the triad is animated in the recording (and in its
    ``StaticHtml()``) as well as drawn live. Stateless; no outputs.
    """

    def __init__(
        self,
        meshcat: Meshcat,
        path: str,
        period_s: float = 1.0 / 32.0,
        style: TriadStyle | None = None,
    ) -> None:
        """
        Args:
            meshcat: where to draw.
            path: the triad's Meshcat path (see :mod:`rlfd_drake.view`).
            period_s: publish period, s.
            style: size and opacity of the triad.
        """
        super().__init__()
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ValueError(f"period_s must be a positive number of seconds, got {period_s}")
        if not path:
            raise ValueError(f"path must be a non-empty Meshcat path, got {path!r}")
        self._meshcat = meshcat
        self._path = path
        self._pose_port = self.DeclareVectorInputPort("X_WE", 7)
        self.DeclareInitializationPublishEvent(self._publish)
        self.DeclarePeriodicPublishEvent(period_s, 0.0, self._publish)
        AddTriad(meshcat, path, style)

    @property
    def path(self) -> str:
        """The triad's Meshcat path."""
        return self._path

    def _publish(self, context: Context) -> EventStatus:
        x = np.asarray(self._pose_port.Eval(context), dtype=float)
        if not np.all(np.isfinite(x)) or np.linalg.norm(x[3:]) < 1e-9:
            # Drawing must never stop a simulation; a bad set-point is the controller's
            # and the observer's to report.
            return EventStatus.DidNothing()
        SetTriadPose(
            self._meshcat, self._path, pose_vector_to_rigid_transform(x), context.get_time()
        )
        return EventStatus.Succeeded()
