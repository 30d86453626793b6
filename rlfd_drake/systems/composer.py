"""Residual composition (paper Section III-D): final set-point = base (+) residual."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from rlfd_drake.control_math import (
    RESIDUAL_MODES,
    quat_exp_rotation_vector,
    quat_multiply_scalar,
    scale_residual,
)


@dataclass(frozen=True)
class ResidualComposerConfig:
    """Attributes:
    max_translation_m: translation per unit of residual action, m.
    max_rotation_rad: rotation-vector component per unit of action, rad (the angle
        alpha = |rotation vector| is bounded to [0, pi]).
    mode: "full", "translation", "orientation" or "off".
    activation_time_s: the residual is zero before this time (the paper's
        simulation runs the DMP alone for the first half of a 10 s episode), s.
    max_push_m: the most the residual may move the set-point down (world -z, into
        the fixtures), m; None = ``max_translation_m`` like the other directions.
    """

    max_translation_m: float = 0.02
    max_rotation_rad: float = 0.26
    mode: str = "full"
    activation_time_s: float = 5.0
    max_push_m: float | None = None


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
      vector]`` scaled by ``max_translation_m`` and ``max_rotation_rad`` (dp's
      downward part limited to ``max_push_m`` if set).
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
        if config.max_push_m is not None and not (
            np.isfinite(config.max_push_m) and config.max_push_m >= 0.0
        ):
            raise ValueError(f"max_push_m must be a number >= 0 or None, got {config.max_push_m}")
        self.config = config
        self._cached_key: bytes | None = None
        self._cached_correction: tuple[np.ndarray, tuple[float, ...]] = (
            np.zeros(3),
            (1.0, 0, 0, 0),
        )
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
        dp, Q_delta = self._correction(residual)
        X = np.empty(7)
        X[:3] = X_WE_base[:3] + dp
        X[3:] = quat_multiply_scalar(Q_delta, X_WE_base[3:])
        return X

    def _correction(self, residual: np.ndarray) -> tuple[np.ndarray, tuple[float, ...]]:
        """(dp (3,) m, Q_delta wxyz) of a residual action. The residual is held for many
        controller ticks (10 Hz against 500 Hz), so the last one is cached."""
        key = residual.tobytes()
        if key != self._cached_key:
            if not np.all(np.isfinite(residual)):
                raise RuntimeError(
                    f"ResidualComposer: non-finite value on port 'residual': {residual}"
                )
            dp, rotvec = scale_residual(
                residual,
                self.config.max_translation_m,
                self.config.max_rotation_rad,
                self.config.mode,
                self.config.max_push_m,
            )
            self._cached_key = key
            self._cached_correction = (dp, quat_exp_rotation_vector(*rotvec))
        return self._cached_correction

    def _calc_X(self, context: Context, output: BasicVector) -> None:
        X_base = self._X_port.Eval(context)
        if self.config.mode == "off" or context.get_time() < self.config.activation_time_s:
            output.SetFromVector(X_base)
            return
        out = output.get_mutable_value()
        out[:] = self.Compose(X_base, self._residual_port.Eval(context))

    def _calc_V(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._V_port.Eval(context))
