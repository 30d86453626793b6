"""Residual composition (paper Section III-D): final set-point = base (+) residual."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis, Quaternion
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from rlfd_drake.control_math import RESIDUAL_MODES, scale_residual


@dataclass(frozen=True)
class ResidualComposerConfig:
    """Attributes:
    max_translation_m: translation per unit of residual action, m.
    max_rotation_rad: rotation-vector component per unit of action, rad (the angle
        alpha = |rotation vector| is bounded to [0, pi]).
    mode: "full", "translation", "orientation" or "off".
    activation_time_s: the residual is zero before this time (the paper's
        simulation runs the DMP alone for the first half of a 10 s episode), s.
    """

    max_translation_m: float = 0.02
    max_rotation_rad: float = 0.26
    mode: str = "full"
    activation_time_s: float = 5.0


class ResidualComposer(LeafSystem):
    """Adds a (held) residual pose correction to the base set-point.

    .. pydrake_system::

        name: ResidualComposer
        input_ports:
        - X_WE_base
        - V_WE_base
        - residual
        output_ports:
        - X_WE_desired
        - V_WE_desired

    * ``X_WE_base`` (7): base pose, position (m) then quaternion [w, x, y, z].
    * ``V_WE_base`` (6): base spatial velocity [w (rad/s); v (m/s)], world.
    * ``residual`` (6): normalised action in [-1, 1] (clipped): ``[dp; rotation
      vector]`` scaled by ``max_translation_m`` and ``max_rotation_rad``.
    * ``X_WE_desired`` (7): ``p_f = p_b + dp``, ``Q_f = Q_delta o Q_b`` with
      ``Q_delta = [cos(alpha/2), r/|r| sin(alpha/2)]`` (world-frame rotation).
    * ``V_WE_desired`` (6): the base twist, passed through (the residual is held
      between policy updates, so it adds no velocity).

    Stateless. A non-finite residual raises RuntimeError (NaN must never reach the
    controller). Before ``activation_time_s`` and in mode "off" the base pose is
    passed through untouched.
    """

    def __init__(
        self,
        config: ResidualComposerConfig = ResidualComposerConfig(),  # noqa: B008
    ):
        super().__init__()
        if config.mode not in RESIDUAL_MODES:
            raise ValueError(f"mode must be one of {RESIDUAL_MODES}, got {config.mode!r}")
        if config.max_translation_m < 0.0 or config.max_rotation_rad < 0.0:
            raise ValueError("max_translation_m and max_rotation_rad must be >= 0")
        self.config = config
        self._X_port = self.DeclareVectorInputPort("X_WE_base", 7)
        self._V_port = self.DeclareVectorInputPort("V_WE_base", 6)
        self._residual_port = self.DeclareVectorInputPort("residual", 6)
        self.DeclareVectorOutputPort(
            "X_WE_desired",
            7,
            self._calc_X,
            prerequisites_of_calc={
                self.time_ticket(),
                self._X_port.ticket(),
                self._residual_port.ticket(),
            },
        )
        self.DeclareVectorOutputPort(
            "V_WE_desired", 6, self._calc_V, prerequisites_of_calc={self._V_port.ticket()}
        )

    def Compose(self, X_WE_base: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """(7,) final pose for a base pose (7,) and an active residual action (6,)."""
        if not np.all(np.isfinite(residual)):
            raise RuntimeError(f"ResidualComposer: non-finite value on port 'residual': {residual}")
        dp, rotvec = scale_residual(
            residual, self.config.max_translation_m, self.config.max_rotation_rad, self.config.mode
        )
        X = X_WE_base.copy()
        X[:3] += dp
        alpha = float(np.sqrt(rotvec @ rotvec))
        if alpha > 0.0:
            Q_delta = AngleAxis(alpha, rotvec / alpha).quaternion()
            X[3:] = Q_delta.multiply(Quaternion(X_WE_base[3:])).wxyz()
        return X

    def _calc_X(self, context: Context, output: BasicVector) -> None:
        X_base = self._X_port.Eval(context)
        if self.config.mode == "off" or context.get_time() < self.config.activation_time_s:
            output.SetFromVector(X_base)
            return
        output.SetFromVector(self.Compose(X_base, self._residual_port.Eval(context)))

    def _calc_V(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._V_port.Eval(context))
