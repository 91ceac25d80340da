"""Constant-velocity Kalman tracker of the object to pick (the paper's Eq. 4-7).

State ``s = [x, y, x', y']`` and measurement ``z = [x, y]`` (Eq. 5) in one of two frames:

* ``"belt"`` (default): x, y in metres in the world's belt plane (world x across the belt,
  y along it, the belt moving along +y). Detections are back-projected with the camera
  pose of their capture time (:mod:`stackpick_sim.estimation.backproject`), so the arm's own
  motion, which the paper's Fig. 9 shows mixed into the image motion, drops out and the
  object really does move at constant velocity.
* ``"image"``: x, y in pixels, the paper's variant. The pixels are those of one camera pose;
  when the camera moves, :meth:`ConstantVelocityTracker.transform` carries the state into
  the new pose's image (the caller supplies the map, e.g. through the face plane), so the
  camera's motion does not enter the state as acceleration.

Noise model (continuous white-noise acceleration, Bar-Shalom et al. 2001, sec. 6.2.2):
over an interval ``dt`` each axis gets ``Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]``, with
``q`` the acceleration spectral density (units^2/s^3). The paper's ``n(k)``, the belt's speed
jitter, gives ``q = 2 sigma_v^2 / tau`` for a speed wandering with standard deviation
``sigma_v`` and correlation time ``tau`` (an Ornstein-Uhlenbeck speed). ``R = sigma^2 I`` with
``sigma`` the detector's pixel noise, or in the belt frame ``sigma_px * Z / f`` metres (a
per-measurement R from :func:`...backproject.plane_backprojection_jacobian` is exact for
oblique views). Measurements carry their image *capture* time; frames arrive at irregular
intervals and late, so every step uses its own ``dt``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
from filterpy.kalman import KalmanFilter
from numpy.typing import NDArray

from stackpick_sim.exceptions import ConfigError, EstimationError

FloatArray = NDArray[np.float64]
TrackerFrame = Literal["belt", "image"]

#: Belt speed jitter, m/s standard deviation: placeholder (0.5 % of a 0.2 m/s belt, the order
#: of a speed-controlled conveyor drive's ripple), not identified on the cell; the scene's
#: configured jitter should replace it.
BELT_SPEED_JITTER_STD = 0.001
#: Correlation time of the belt speed jitter, s: placeholder, not identified.
BELT_JITTER_TIME = 0.5
#: Detector centre noise, px standard deviation: placeholder; the paper reports < 2 px mean
#: pose error, a sub-pixel ellipse fit on clean renders does better.
PIXEL_NOISE_STD = 0.5
#: Mahalanobis gate, chi^2 with 2 dof at 99.9 %: a true measurement is rejected once in 1000.
GATE_CHI2 = 13.8155
#: Log-likelihood ratio (nats) past which the measurements say an object left its prior
#: velocity: ln 1000, one false alarm in about a thousand measurements of a true prior.
PRIOR_EVIDENCE = 6.9
#: Reason prefix of a two-point start refused because the pair's velocity disagrees with the
#: prior velocity: the newer measurement is kept as the next start's first.
PRIOR_RESTART = "initialising: pair off the prior velocity"
#: Consecutive gated-out measurements after which the track is declared lost (at 30 Hz,
#: 5 frames = 0.17 s without a plausible detection). Placeholder.
MAX_CONSECUTIVE_REJECTIONS = 5


def belt_accel_psd(speed_jitter_std: float = BELT_SPEED_JITTER_STD,
                   jitter_time: float = BELT_JITTER_TIME) -> float:
    """Acceleration spectral density q (m^2/s^3) of a belt speed jittering by ``sigma_v`` m/s.

    An Ornstein-Uhlenbeck speed with stationary std ``sigma_v`` and correlation time ``tau``
    is driven by white acceleration of density ``2 sigma_v^2 / tau``.
    """
    if speed_jitter_std < 0.0 or jitter_time <= 0.0:
        raise ConfigError(f"need speed_jitter_std >= 0 m/s and jitter_time > 0 s; got "
                          f"{speed_jitter_std}, {jitter_time}")
    return 2.0 * speed_jitter_std**2 / jitter_time


@dataclass(frozen=True, kw_only=True)
class TrackerConfig:
    """Settings of :class:`ConstantVelocityTracker`; units are the frame's (m or px).

    ``accel_psd`` q (units^2/s^3), ``measurement_std`` (units), ``max_speed`` (units/s) the
    fastest plausible object speed, used to reject a wild first pair of measurements.
    ``prior_velocity`` (units/s, (vx, vy)) with ``prior_velocity_std`` (units/s), when given,
    is what the velocity is expected to be before any measurement (an object riding a belt
    of known speed): fused with the velocity of every two-point start, restarts included.
    A first pair whose velocity lies outside ``gate_chi2`` of it (the pair's covariance plus
    the prior's) is not used: one of the two was not the face; the older is dropped.

    ``prior_velocity_time`` (s, 0: off) keeps the prior after the start: between
    measurements the velocity's deviation from ``prior_velocity`` relaxes towards zero with
    this time constant (an object carried by the belt, whose own motion -- settling in its
    pile, a nudge -- dies out), so a velocity that measurement bias pulled off the prior
    does not carry on into a blind extrapolation, and a few biased measurements in a row
    are gated out rather than taken for a changed motion. An innovation test keeps it from
    gluing an object that truly moves on its own: a second filter runs on the same
    measurements without the relaxation; once the measurements are
    ``prior_velocity_evidence`` (nats, log-likelihood ratio, summed with a floor at 0: a
    CUSUM) more likely under it, the tracker is that filter for the rest of the track.
    """

    frame: TrackerFrame = "belt"
    accel_psd: float
    measurement_std: float
    max_speed: float
    gate_chi2: float = GATE_CHI2
    max_consecutive_rejections: int = MAX_CONSECUTIVE_REJECTIONS
    prior_velocity: tuple[float, float] | None = None
    prior_velocity_std: float = 0.0
    prior_velocity_time: float = 0.0
    prior_velocity_evidence: float = PRIOR_EVIDENCE

    def __post_init__(self) -> None:
        if self.frame not in ("belt", "image"):
            raise ConfigError(f"unknown tracker frame '{self.frame}'; known: belt, image")
        if self.accel_psd < 0.0 or self.measurement_std <= 0.0 or self.max_speed <= 0.0:
            raise ConfigError(f"need accel_psd >= 0, measurement_std > 0, max_speed > 0; got "
                              f"{self.accel_psd}, {self.measurement_std}, {self.max_speed}")
        if self.gate_chi2 <= 0.0 or self.max_consecutive_rejections < 1:
            raise ConfigError(f"need gate_chi2 > 0 and max_consecutive_rejections >= 1; got "
                              f"{self.gate_chi2}, {self.max_consecutive_rejections}")
        if self.prior_velocity is not None and not (
                len(self.prior_velocity) == 2 and np.all(np.isfinite(self.prior_velocity))
                and np.isfinite(self.prior_velocity_std) and self.prior_velocity_std > 0.0):
            raise ConfigError(f"need a finite (vx, vy) prior_velocity and prior_velocity_std "
                              f"> 0; got {self.prior_velocity}, {self.prior_velocity_std}")
        if not (self.prior_velocity_time >= 0.0 and self.prior_velocity_evidence > 0.0):
            raise ConfigError(f"need prior_velocity_time >= 0 s and prior_velocity_evidence > "
                              f"0; got {self.prior_velocity_time}, "
                              f"{self.prior_velocity_evidence}")

    @classmethod
    def belt(cls, *, depth: float, focal_px: float, pixel_std: float = PIXEL_NOISE_STD,
             accel_psd: float | None = None, max_speed: float = 1.0,
             prior_velocity: tuple[float, float] | None = None,
             prior_velocity_std: float = 0.0, prior_velocity_time: float = 0.0,
             prior_velocity_evidence: float = PRIOR_EVIDENCE) -> TrackerConfig:
        """Belt-frame config: R from ``pixel_std`` px at ``depth`` m and focal ``focal_px`` px.

        ``accel_psd`` defaults to :func:`belt_accel_psd` (m^2/s^3); ``max_speed`` m/s;
        ``prior_velocity`` (m/s) e.g. the belt's, with ``prior_velocity_std`` m/s, held with
        ``prior_velocity_time`` s under the test ``prior_velocity_evidence`` (see the class).
        """
        q = belt_accel_psd() if accel_psd is None else accel_psd
        return cls(frame="belt", accel_psd=q, measurement_std=pixel_std * depth / focal_px,
                   max_speed=max_speed, prior_velocity=prior_velocity,
                   prior_velocity_std=prior_velocity_std,
                   prior_velocity_time=prior_velocity_time,
                   prior_velocity_evidence=prior_velocity_evidence)

    @classmethod
    def image(cls, *, accel_psd: float, pixel_std: float = PIXEL_NOISE_STD,
              max_speed: float = 2000.0) -> TrackerConfig:
        """Image-frame config (paper's variant): q in px^2/s^3, must cover camera motion too."""
        return cls(frame="image", accel_psd=accel_psd, measurement_std=pixel_std,
                   max_speed=max_speed)


class Prediction(NamedTuple):
    """Filter state extrapolated to a time: (2,) position, (2,) velocity, (4, 4) covariance."""

    position: FloatArray
    velocity: FloatArray
    covariance: FloatArray


@dataclass(frozen=True)
class UpdateResult:
    """Outcome of one measurement; falsy when it was not used, ``reason`` says why."""

    accepted: bool
    reason: str
    mahalanobis_sq: float = 0.0

    def __bool__(self) -> bool:
        return self.accepted


def transition(dt: float) -> FloatArray:
    """(4, 4) constant-velocity transition A over ``dt`` s (Eq. 5a)."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    return f


def relaxed_transition(dt: float, prior_velocity: FloatArray,
                       time: float) -> tuple[FloatArray, FloatArray]:
    """(4, 4) F and (4,) offset c over ``dt`` s of a velocity relaxing to ``prior_velocity``.

    The velocity's deviation ``u`` from the (2,) prior decays as ``exp(-t / time)`` (``time``
    s > 0): ``v' = v_p + a u`` and ``x' = x + v_p dt + time (1 - a) u`` with
    ``a = exp(-dt / time)``; the state moves as ``s' = F s + c``.
    """
    a = float(np.exp(-dt / time))
    b = time * (1.0 - a)
    f = np.eye(4)
    f[0, 2] = f[1, 3] = b
    f[2, 2] = f[3, 3] = a
    vp = np.asarray(prior_velocity, dtype=float).reshape(2)
    return f, np.concatenate([(dt - b) * vp, (1.0 - a) * vp])


def process_noise(dt: float, accel_psd: float) -> FloatArray:
    """(4, 4) Q over ``dt`` s for white acceleration of density ``accel_psd`` on each axis."""
    q = np.zeros((4, 4))
    for pos, vel in ((0, 2), (1, 3)):
        q[pos, pos] = dt**3 / 3.0
        q[pos, vel] = q[vel, pos] = dt**2 / 2.0
        q[vel, vel] = dt
    return accel_psd * q


_H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])


def _innovation(kf: KalmanFilter, z: FloatArray, r: FloatArray) -> tuple[float, float]:
    """Squared Mahalanobis distance of measurement ``z`` (2,) from ``kf``'s predicted one
    (covariance R ``r``), and the log-determinant of the innovation covariance."""
    innovation = z - _H @ kf.x.reshape(4)
    s = _H @ kf.P @ _H.T + r
    return float(innovation @ np.linalg.solve(s, innovation)), float(np.linalg.slogdet(s)[1])


class ConstantVelocityTracker:
    """filterpy KalmanFilter with irregular dt, two-point start, gating and lost-track count."""

    def __init__(self, config: TrackerConfig) -> None:
        self.config = config
        self._kf = KalmanFilter(dim_x=4, dim_z=2)
        self._kf.H = _H.copy()
        self._free: KalmanFilter | None = None
        """With a held prior (``prior_velocity_time``): the same filter without the
        relaxation, for the innovation test."""
        if config.prior_velocity is not None and config.prior_velocity_time > 0.0:
            self._free = KalmanFilter(dim_x=4, dim_z=2)
            self._free.H = _H.copy()
        self.on_prior = True
        """Whether the velocity relaxes to the prior: the innovation test has not failed
        since the track started, nor has a :meth:`restart` taken a changed motion (always
        True without a held prior)."""
        self._evidence = 0.0
        """The innovation test's CUSUM of log-likelihood ratios (:meth:`_test_prior`)."""
        self._default_r = np.eye(2) * config.measurement_std**2
        self._first: tuple[float, FloatArray, FloatArray] | None = None
        self._time: float | None = None
        self.consecutive_rejections = 0

    @property
    def initialised(self) -> bool:
        """True once two consistent measurements have set the state."""
        return self._time is not None

    @property
    def lost_track(self) -> bool:
        """True after ``max_consecutive_rejections`` measurements in a row failed the gate."""
        return self.consecutive_rejections >= self.config.max_consecutive_rejections

    @property
    def time(self) -> float | None:
        """Capture time (s) of the last measurement fused, None before initialisation."""
        return self._time

    def update(self, t: float, z: FloatArray, r: FloatArray | None = None) -> UpdateResult:
        """Fuse a (2,) measurement captured at ``t`` s, with optional (2, 2) covariance ``r``.

        Measurements older than the state are dropped ("stale"); a measurement outside the
        Mahalanobis gate is dropped ("gated") and counts towards :attr:`lost_track`.
        """
        zv = np.asarray(z, dtype=float).reshape(2)
        rv = self._default_r if r is None else np.asarray(r, dtype=float).reshape(2, 2)
        if not np.all(np.isfinite(zv)):
            raise EstimationError(f"measurement must be finite; got {zv}")
        if self._time is None:
            return self._initialise(t, zv, rv)
        dt = t - self._time
        if dt < 0.0:
            return UpdateResult(False, f"stale: captured at {t:.4f} s, state at {self._time:.4f} s")
        self._predict(dt, self.config.accel_psd)
        self._time = t
        d2, log_det = _innovation(self._kf, zv, rv)
        if self._free is not None:
            d2_free, log_det_free = _innovation(self._free, zv, rv)
            if d2_free <= self.config.gate_chi2:
                self._free.update(zv.reshape(2, 1), R=rv)
                if self.on_prior:
                    self._test_prior(0.5 * (d2 + log_det - d2_free - log_det_free))
            if not self.on_prior:  # off the prior the tracker is the free filter
                self._kf.x, self._kf.P = self._free.x.copy(), self._free.P.copy()
                d2 = d2_free
        if d2 > self.config.gate_chi2:
            self.consecutive_rejections += 1
            return UpdateResult(False, f"gated: Mahalanobis^2 {d2:.1f} > {self.config.gate_chi2}",
                                d2)
        if self.on_prior or self._free is None:
            self._kf.update(zv.reshape(2, 1), R=rv)
        self.consecutive_rejections = 0
        return UpdateResult(True, "fused", d2)

    def _predict(self, dt: float, accel_psd: float) -> None:
        """Both filters forward by ``dt`` s >= 0; the tracker's relaxes to the prior while
        :attr:`on_prior`."""
        q = process_noise(dt, accel_psd)
        if self._free is None:
            self._kf.predict(F=transition(dt), Q=q)
            return
        self._free.predict(F=transition(dt), Q=q)
        if self.on_prior:
            assert self.config.prior_velocity is not None
            f, c = relaxed_transition(dt, np.asarray(self.config.prior_velocity),
                                      self.config.prior_velocity_time)
            self._kf.predict(u=c.reshape(4, 1), B=np.eye(4), F=f, Q=q)
        else:
            self._kf.predict(F=transition(dt), Q=q)

    def _test_prior(self, log_ratio: float) -> None:
        """The innovation test of the held prior (a CUSUM, Page 1954): ``log_ratio`` is how
        much less likely the latest measurement is under the filter held to the prior than
        under the free one; summed, floored at 0, past ``prior_velocity_evidence`` the object
        moves on its own: the tracker takes the free state, for the rest of the track."""
        assert self._free is not None
        self._evidence = max(0.0, self._evidence + log_ratio)
        self.on_prior = self._evidence <= self.config.prior_velocity_evidence

    def advance(self, t: float, accel_psd: float | None = None) -> bool:
        """Predict the state forward to ``t`` s without a measurement; False if ``t`` is older.

        ``accel_psd`` overrides the config's q for this step (units^2/s^3), e.g. an image
        frame whose pixel scale changes with the camera's depth.
        """
        if self._time is None:
            raise EstimationError("advance needs an initialised tracker (two measurements)")
        dt = t - self._time
        if dt < 0.0:
            return False
        self._predict(dt, self.config.accel_psd if accel_psd is None else accel_psd)
        self._time = t
        return True

    def transform(self, position: FloatArray, jacobian: FloatArray) -> None:
        """Re-express the state in another frame, e.g. the image of a moved camera.

        ``position`` (2,) is the current position mapped into the new frame and
        ``jacobian`` (2, 2) that map's derivative there: velocity and covariance are
        carried through it (first order, as an extended Kalman filter does).
        """
        if self._time is None:
            raise EstimationError("transform needs an initialised tracker (two measurements)")
        j = np.asarray(jacobian, dtype=float).reshape(2, 2)
        t = np.zeros((4, 4))
        t[:2, :2] = t[2:, 2:] = j
        x = self._kf.x.reshape(4)
        self._kf.x = np.concatenate([np.asarray(position, dtype=float).reshape(2),
                                     j @ x[2:]]).reshape(4, 1)
        self._kf.P = t @ self._kf.P @ t.T
        if self._free is not None:
            xf = self._free.x.reshape(4)
            self._free.x = np.concatenate([self._kf.x.reshape(4)[:2], j @ xf[2:]]).reshape(4, 1)
            self._free.P = t @ self._free.P @ t.T

    def restart(self, t0: float, z0: FloatArray, r0: FloatArray, t1: float, z1: FloatArray,
                r1: FloatArray) -> UpdateResult:
        """Forget the state and start again from two (2,) measurements at ``t0 < t1`` s.

        For a target that changed its motion (an object shifting in its pile): a run of
        gated-out but mutually consistent measurements is the target, not clutter.
        """
        self._time = None
        self._first = None
        self.consecutive_rejections = 0
        self._initialise(t0, np.asarray(z0, dtype=float), np.asarray(r0, dtype=float))
        # The caller has checked the pair (three collinear detections, or the image frame's
        # own start): it is the new motion even when the belt's prior disagrees, and a held
        # prior is not held on to for the rest of the track.
        result = self._initialise(t1, np.asarray(z1, dtype=float), np.asarray(r1, dtype=float),
                                  check_prior=False)
        if self._free is not None and result:
            self._free.x, self._free.P = self._kf.x.copy(), self._kf.P.copy()
            self.on_prior = False
        return result

    def predict_at(self, t: float) -> Prediction:
        """Position, velocity and covariance extrapolated to ``t`` s (Eq. 4); no state change.

        Forward, a velocity held to the prior (:attr:`on_prior`) relaxes towards it as in
        :func:`relaxed_transition`. ``t`` may be before the last measurement (extrapolating
        backwards, at constant velocity). Raises
        EstimationError before initialisation.
        """
        if self._time is None:
            raise EstimationError("predict_at needs an initialised tracker (two measurements)")
        dt = t - self._time
        f, c = transition(dt), np.zeros(4)
        if self._free is not None and self.on_prior and dt > 0.0:
            assert self.config.prior_velocity is not None
            f, c = relaxed_transition(dt, np.asarray(self.config.prior_velocity),
                                      self.config.prior_velocity_time)
        x = f @ self._kf.x.reshape(4) + c
        p = f @ self._kf.P @ f.T + process_noise(abs(dt), self.config.accel_psd)
        return Prediction(x[:2].copy(), x[2:].copy(), p)

    def _initialise(self, t: float, z: FloatArray, r: FloatArray, *,
                    check_prior: bool = True) -> UpdateResult:
        # The paper: "the first measurements of the object's position and speed are given as
        # the initial state" -- position from the newest, speed from the difference of two.
        # With a prior velocity the pair must also agree with it (``check_prior``).
        if self._first is None:
            self._first = (t, z, r)
            return UpdateResult(False, "initialising: first measurement stored")
        t0, z0, r0 = self._first
        dt = t - t0
        if dt <= 0.0:
            self._first = (t, z, r) if dt < 0.0 else self._first
            return UpdateResult(False, f"initialising: need increasing times, got dt={dt:.4f} s")
        v = (z - z0) / dt
        speed = float(np.linalg.norm(v))
        if speed > self.config.max_speed:
            self._first = (t, z, r)
            return UpdateResult(False, f"initialising: implied speed {speed:.3g} > max_speed "
                                       f"{self.config.max_speed}; restarted from this one")
        p = np.zeros((4, 4))
        p[:2, :2] = r
        p[:2, 2:] = p[2:, :2] = r / dt
        p[2:, 2:] = (r + r0) / dt**2
        prior_v = self.config.prior_velocity
        if prior_v is not None and check_prior:
            # Two detections of one face moving with the belt imply its velocity to within
            # their covariance and the prior's. Beyond the gate, one of the two is not where
            # the face was (two different ellipses of one face, 3 mm apart a frame apart):
            # which one is unknown, so the older is dropped and the newer pairs with the
            # next; a wrong newer one is dropped there in turn. Fusing the pair instead
            # would start the filter a few mm off with a tight covariance, and the right
            # detections that follow would be gated out.
            dv = v - np.asarray(prior_v, dtype=float)
            s_v = p[2:, 2:] + np.eye(2) * self.config.prior_velocity_std**2
            d2 = float(dv @ np.linalg.solve(s_v, dv))
            if d2 > self.config.gate_chi2:
                self._first = (t, z, r)
                return UpdateResult(False, f"{PRIOR_RESTART}: implied {np.round(v, 4)}, prior "
                                           f"{prior_v}, Mahalanobis^2 {d2:.1f} > "
                                           f"{self.config.gate_chi2}; restarted from this one")
        measured = (np.concatenate([z, v]), p.copy())  # the free filter's start: no prior
        if prior_v is not None:
            # Two detections a frame apart give the speed to ~20 mm/s (belt frame); the belt
            # knows it far better. A velocity measurement, fused once.
            h = np.hstack([np.zeros((2, 2)), np.eye(2)])
            s = h @ p @ h.T + np.eye(2) * self.config.prior_velocity_std**2
            gain = p @ h.T @ np.linalg.inv(s)
            x = np.concatenate([z, v])
            x = x + gain @ (np.asarray(prior_v, dtype=float) - v)
            p = (np.eye(4) - gain @ h) @ p
            z, v = x[:2], x[2:]
        self._kf.x = np.concatenate([z, v]).reshape(4, 1)
        self._kf.P = p
        if self._free is not None:
            self._free.x = measured[0].reshape(4, 1)
            self._free.P = measured[1]
            self.on_prior = True
            self._evidence = 0.0
        self._time = t
        self._first = None
        return UpdateResult(True, "initialised from two measurements")
