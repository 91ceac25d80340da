"""The eye-in-hand visual servo law: damped pseudo-inverse, adaptive gain, feed-forward.

``qdot = -lambda(|e|) * J^+ e - J^+ de/dt_hat`` (Chaumette & Hutchinson 2006, Eq. 27 with the
target-motion term of ViSP's servoViper850Point2DCamVelocityKalman), with the image
Jacobian ``J = L @ c_V_e @ e_J_e`` (k, n) built by
:meth:`stackpick_sim.control.eye_in_hand.EyeInHand.image_jacobian`, ``e = s - s*`` (k,)
and ``de/dt_hat`` (k,) the feature rate caused by the target's own motion, from the Kalman
velocity (:func:`target_feature_rate`). This is the paper's Eq. 18 ``u = lambda J^+ (P_n -
P_c)`` written for the error ``e = P_c - P_n`` plus the moving-target term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from stackpick_sim.exceptions import ConfigError, ControlError

FloatArray = NDArray[np.float64]

#: Adaptive-gain defaults (1/s). The form and lambda'(0) = 30 are ViSP's tutorial values
#: (vpAdaptiveGain(4, 0.4, 30) in tutorial-ibvs-4pts). ViSP's gains left the kinematic
#: servo test (tests/test_control.py: 4 cm offset, 15 deg tilt, 30 Hz) > 20 mm off after
#: 1.5 s; (10, 4) converges to < 1 mm and < 0.5 deg in 0.6 s and keeps lambda * dt = 0.33 at
#: 30 Hz, well inside the discrete stability bound of 2. Tuned in simulation, not on hardware.
GAIN_AT_ZERO = 10.0
GAIN_AT_INFINITY = 4.0
GAIN_SLOPE_AT_ZERO = 30.0

#: Damped least squares (Nakamura & Hanafusa 1986; Maciejewski & Klein 1988 for the rule):
#: damping ``rho^2 = (1 - (sigma_min / eps)^2) * rho_max^2`` switches on only when the
#: smallest singular value of J drops below ``eps``, so away from singularities J^+ is Eq. 17
#: exactly. Units of J's singular values: feature units per rad (features are dimensionless).
#: On the VS-060 with the circle-pose features sigma_min is 0.34-0.47 at ordinary servo poses
#: and falls roughly in proportion to J5 near the wrist singularity (0.136 at J5 = 0.35 rad,
#: 0.016 at 0.047 rad, servoing to a paper-scene face tilted 38 deg towards the robot). With
#: eps = 0.02 the undamped inverse spins J4 at its speed limit chasing the last degrees of
#: tilt while the lateral error grows to 25 mm; eps = 0.1 (J5 ~ 0.25 rad) and rho_max = 0.05
#: give up a little tilt there instead. Tuned in simulation on paper scenes, not on hardware.
DAMPING_THRESHOLD = 0.1
MAX_DAMPING = 0.05


@dataclass(frozen=True, kw_only=True)
class AdaptiveGain:
    """ViSP's adaptive gain ``lambda(x) = (l0 - linf) exp(-l0' x / (l0 - linf)) + linf``, 1/s.

    High near convergence (fast final approach without overshoot far away), ``x = |e|_inf``.
    """

    at_zero: float = GAIN_AT_ZERO
    at_infinity: float = GAIN_AT_INFINITY
    slope_at_zero: float = GAIN_SLOPE_AT_ZERO

    def __post_init__(self) -> None:
        if not 0.0 < self.at_infinity <= self.at_zero:
            raise ConfigError(f"adaptive gain needs 0 < at_infinity <= at_zero; got "
                              f"at_infinity={self.at_infinity}, at_zero={self.at_zero}")
        if self.slope_at_zero < 0.0:
            raise ConfigError(f"adaptive gain slope_at_zero must be >= 0; got {self.slope_at_zero}")

    def __call__(self, error_norm: float) -> float:
        """Gain (1/s) for an error of infinity-norm ``error_norm`` (feature units)."""
        span = self.at_zero - self.at_infinity
        if span == 0.0:
            return self.at_zero
        return span * math.exp(-self.slope_at_zero * error_norm / span) + self.at_infinity


@dataclass(frozen=True, kw_only=True)
class ServoConfig:
    """Visual servo settings; see the module constants for the sources of the defaults."""

    gain: AdaptiveGain = field(default_factory=AdaptiveGain)
    damping_threshold: float = DAMPING_THRESHOLD
    max_damping: float = MAX_DAMPING
    feed_forward: bool = True

    def __post_init__(self) -> None:
        if self.damping_threshold <= 0.0 or self.max_damping < 0.0:
            raise ConfigError(f"need damping_threshold > 0 and max_damping >= 0; got "
                              f"{self.damping_threshold}, {self.max_damping}")


def damped_pinv(jacobian: FloatArray, threshold: float = DAMPING_THRESHOLD,
                max_damping: float = MAX_DAMPING) -> FloatArray:
    """(n, k) damped pseudo-inverse of a (k, n) Jacobian.

    ``J^+ = V diag(s / (s^2 + rho^2)) U^T``: with ``rho = 0`` this is Eq. 17 (the
    Moore-Penrose inverse, ``(J^T J)^-1 J^T`` when J has full column rank); ``rho`` grows
    smoothly from 0 to ``max_damping`` as the smallest singular value falls from
    ``threshold`` to 0, bounding the joint rate near singular configurations.
    """
    j = np.asarray(jacobian, dtype=float)
    u, s, vt = np.linalg.svd(j, full_matrices=False)
    s_min = float(s[-1]) if s.size else 0.0
    rho2 = 0.0
    if s_min < threshold:
        rho2 = (1.0 - (s_min / threshold) ** 2) * max_damping**2
    denom = s**2 + rho2
    inv = np.divide(s, denom, out=np.zeros_like(s), where=denom > 1e-300)
    return np.asarray((vt.T * inv) @ u.T)


def target_feature_rate(interaction: FloatArray, cam_R_world: FloatArray,
                        target_velocity_world: FloatArray) -> FloatArray:
    """(k,) ``de/dt`` caused by a target translating at (3,) m/s (world) under a still camera.

    With the belt tracker, ``target_velocity_world = (vx, vy, 0)`` from
    ``ConstantVelocityTracker.predict_at(t).velocity``.

    A target moving at ``v`` looks like the camera moving at ``-v`` (translation only, the
    face's normal keeps its direction): ``de/dt = L[:, :3] @ (-cam_R_world @ v)``.
    ``interaction`` (k, 6) is L at the current features, ``cam_R_world`` (3, 3).
    """
    l_mat = np.asarray(interaction, dtype=float)
    v_cam = np.asarray(cam_R_world, dtype=float) @ np.asarray(target_velocity_world, dtype=float)
    return np.asarray(-l_mat[:, :3] @ v_cam)


def servo_velocity(jacobian: FloatArray, error: FloatArray, config: ServoConfig,
                   error_rate_hat: FloatArray | None = None) -> FloatArray:
    """(n,) joint velocities (rad/s) of the law ``-lambda J^+ e - J^+ de/dt_hat``.

    ``jacobian`` (k, n) is ``L c_V_e e_J_e``; ``error`` (k,) is ``s - s*``; ``error_rate_hat``
    (k,) the target-motion feature rate, ignored when ``config.feed_forward`` is False.
    """
    j = np.asarray(jacobian, dtype=float)
    e = np.asarray(error, dtype=float)
    if j.ndim != 2 or e.shape != (j.shape[0],):
        raise ControlError(f"jacobian (k, n) and error (k,) disagree: {j.shape} vs {e.shape}")
    j_pinv = damped_pinv(j, config.damping_threshold, config.max_damping)
    lam = config.gain(float(np.max(np.abs(e))) if e.size else 0.0)
    correction = lam * e
    if config.feed_forward and error_rate_hat is not None:
        correction = correction + np.asarray(error_rate_hat, dtype=float)
    return np.asarray(-j_pinv @ correction)


def saturated_servo_velocity(jacobian: FloatArray, error: FloatArray, config: ServoConfig,
                             speed_limit: FloatArray, error_rate_hat: FloatArray | None = None,
                             primary: int = 3) -> FloatArray:
    """(n,) joint velocities (rad/s) of :func:`servo_velocity`'s law within ``speed_limit``.

    ``speed_limit`` (n,) rad/s. The first ``primary`` feature rows (the face centre: x, y,
    log Z) are the primary task, the rest (the normal) are solved in its null space
    (Siciliano & Slotine 1991). When the joints cannot follow both, the secondary task's
    share is cut first, down to nothing, and only then the primary one (scaled as a whole):
    scaling the whole law instead (as :meth:`JointVelocityExecutor.feasible_velocity` does)
    slows the tool's translation with its turn, and near the wrist singularity, where the
    normal asks J4 for several times its speed, the tool falls behind a face on a
    0.3 m/s belt (the fast_belt scene) by 35 mm. ``jacobian`` (k, n), ``error`` (k,),
    ``error_rate_hat`` (k,) as for :func:`servo_velocity`.
    """
    j = np.asarray(jacobian, dtype=float)
    e = np.asarray(error, dtype=float)
    limit = np.asarray(speed_limit, dtype=float)
    if j.ndim != 2 or e.shape != (j.shape[0],) or limit.shape != (j.shape[1],):
        raise ControlError(f"jacobian (k, n), error (k,) and speed_limit (n,) disagree: "
                           f"{j.shape}, {e.shape}, {limit.shape}")
    if not 0 < primary <= j.shape[0] or np.any(limit <= 0.0):
        raise ControlError(f"need 0 < primary <= {j.shape[0]} and speed limits > 0; got "
                           f"{primary}, {limit}")
    lam = config.gain(float(np.max(np.abs(e))) if e.size else 0.0)
    correction = lam * e
    if config.feed_forward and error_rate_hat is not None:
        correction = correction + np.asarray(error_rate_hat, dtype=float)
    j1, j2 = j[:primary], j[primary:]
    q1 = -damped_pinv(j1, config.damping_threshold, config.max_damping) @ correction[:primary]
    ratio = float(np.max(np.abs(q1) / limit))
    if ratio >= 1.0 or j2.size == 0:
        return np.asarray(q1 / max(ratio, 1.0))
    null = np.eye(j.shape[1]) - np.linalg.pinv(j1) @ j1
    q2 = damped_pinv(j2 @ null, config.damping_threshold, config.max_damping) @ (
        -correction[primary:] - j2 @ q1)
    # Largest share of q2 keeping every joint within its limit (|q1| < limit already).
    moving = np.abs(q2) > 1e-12
    bounds = (np.sign(q2[moving]) * limit[moving] - q1[moving]) / q2[moving]
    share = float(min(1.0, np.min(bounds))) if bounds.size else 1.0
    return np.asarray(q1 + share * q2)
