"""The definitive-attitude state: its layout, the gyro model and the settings of the estimator.

Gyro model (Pittelkau 2001, "Kalman filtering for spacecraft system alignment calibration", J. Guidance
24(6); the linear calibration matrix of e.g. Crassidis & Junkins, Optimal Estimation of Dynamic Systems,
2nd ed., §7.4): in the configured gyro frame G (q_BG of the configuration)

    w_meas,G = (I + K) w_G + b + eta_v,      db/dt = eta_u,

with w_G = R(q_BG)^T w_B the true body rate in G, b the bias (a random walk of rate random walk
sigma_u, rad/s/sqrt(s)), eta_v white rate noise (angle random walk sigma_v, rad/sqrt(s), per gyro axis)
and K the calibration matrix: its diagonal the three scale-factor errors s_x, s_y, s_z, its six
off-diagonal elements Pittelkau's misalignment/non-orthogonality parameters. The antisymmetric part of
the off-diagonal is a small rotation of the whole triad, the symmetric part the non-orthogonality:
K ~ diag(s) + [delta x] + N with delta = ((K_zy - K_yz)/2, (K_xz - K_zx)/2, (K_yx - K_xy)/2) the rotation
vector of q_{G_true G} (for 000's w_meas = (1 + m) S^Delta w + b: K = m I + [Delta x]); exactly, the polar
factors of I + K (:func:`misalignment_parts`).

Star tracker j: q_IS_j(t_tag) = q_IB(t_tag + dt) o q_BS_j o exp(n_j), n_j a rotation vector about the
sensor axes of covariance diag(sigma_j²) (anisotropic: the boresight z is noisier), dt the star-tracker
time-tag error relative to the gyro (the true sample time is the tag plus dt). The first head is the
reference: its configured mounting defines the body frame. A further head's mounting may be estimated
as q_BS_j = q_BS_j,configured o exp(phi_j).

Error state (multiplicative, Markley 2003; Crassidis & Junkins §7.2): q_IB = q^_IB o exp(dtheta) with
dtheta in body axes, then db, then the optional augmented states in this order: scale factors (3),
misalignment (6: K_xy, K_xz, K_yx, K_yz, K_zx, K_zy), head mountings phi_j (3 per further head), time
offset dt (1).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from processing.units import RAD_PER_ARCSEC, RAD_PER_DEG

FloatArray = NDArray[np.float64]

SCALE_NAMES = ("scale_x", "scale_y", "scale_z")
MISALIGNMENT_NAMES = ("K_xy", "K_xz", "K_yx", "K_yz", "K_zx", "K_zy")
K_ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
"""(row, column) of K for the 9 calibration parameters: 3 scale factors, then the 6 misalignments."""


class DefinitiveError(ValueError):
    """Inputs or settings that do not allow the definitive attitude; the message says what and why."""


@dataclass(frozen=True)
class DefinitiveSettings:
    """Settings of :func:`processing.definitive.estimate.estimate_definitive_attitude`.

    Noise: ``gyro_arw_rad_sqrt_s`` angle random walk per gyro axis (None: from the second differences of
    the rates); ``bias_random_walk_rad_s_sqrt_s`` sigma_u; ``star_tracker_sigma_rad`` head -> (3,) sigma
    about the sensor axes (a head not given: from the data, by re-estimating from the smoothed residuals
    between passes; ``initial_star_tracker_sigma_rad`` is the first pass's guess).
    Priors (1 sigma; also the scale of "determined"): attitude, bias, scale factor, misalignment, head
    mounting, time offset. ``passes``: filter/smoother passes (each later pass re-linearises the gyro
    propagation about the previous smoothed calibration and re-estimates the star-tracker noise).
    ``max_block_steps``: longest run of gyro steps between two filter epochs (propagation-only epochs
    are inserted in star-tracker gaps). ``gate_probability``: a head's measurement whose NIS exceeds the
    chi²(3) quantile of 1 - this is rejected as an outlier (0: no gating). ``observability_threshold``:
    a state is determined when the data alone fix it to this fraction of its prior sigma.
    """

    estimate_scale_factors: bool = False
    estimate_misalignment: bool = False
    estimate_head_mounting: bool = False
    estimate_time_offset: bool = False
    gyro_arw_rad_sqrt_s: tuple[float, float, float] | None = None
    bias_random_walk_rad_s_sqrt_s: float = 1e-9
    star_tracker_sigma_rad: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)
    initial_star_tracker_sigma_rad: tuple[float, float, float] = (10 * RAD_PER_ARCSEC, 10 * RAD_PER_ARCSEC,
                                                                   60 * RAD_PER_ARCSEC)
    attitude_sigma_rad: float = 1.0 * RAD_PER_DEG
    bias_sigma_rad_s: float = 1e-4
    scale_factor_sigma: float = 1e-2
    misalignment_sigma_rad: float = 1e-3
    head_mounting_sigma_rad: float = 3e-3
    time_offset_sigma_s: float = 0.1
    passes: int = 4
    max_block_steps: int = 64
    max_gyro_gap_s: float = 5.0
    gate_probability: float = 1e-6
    observability_threshold: float = 0.1

    def __post_init__(self) -> None:
        for name in ("attitude_sigma_rad", "bias_sigma_rad_s", "scale_factor_sigma", "misalignment_sigma_rad",
                     "head_mounting_sigma_rad", "time_offset_sigma_s", "max_gyro_gap_s"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise DefinitiveError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not (np.isfinite(self.bias_random_walk_rad_s_sqrt_s) and self.bias_random_walk_rad_s_sqrt_s >= 0):
            raise DefinitiveError(f"bias_random_walk_rad_s_sqrt_s must be >= 0, got "
                                  f"{self.bias_random_walk_rad_s_sqrt_s!r}")
        if self.passes < 1 or self.max_block_steps < 1:
            raise DefinitiveError(f"passes and max_block_steps must be >= 1, got {self.passes}, "
                                  f"{self.max_block_steps}")
        if not 0 <= self.gate_probability < 0.5:
            raise DefinitiveError(f"gate_probability must be in [0, 0.5), got {self.gate_probability}")
        if not 0 < self.observability_threshold < 1:
            raise DefinitiveError(f"observability_threshold must be in (0, 1), got {self.observability_threshold}")


@dataclass(frozen=True)
class StateLayout:
    """Indices of the error state. ``heads``: star-tracker names, the first the reference; ``mounted``:
    whether the further heads' mountings are states; ``calibration``: the K entries estimated (indices
    into K_ENTRIES); ``time_offset``: whether dt is a state."""

    heads: tuple[str, ...]
    calibration: tuple[int, ...]
    mounted: bool
    time_offset: bool

    @property
    def n_cal(self) -> int:
        return len(self.calibration)

    @property
    def cal(self) -> slice:
        return slice(6, 6 + self.n_cal)

    def mount(self, head: int) -> slice | None:
        """Slice of head ``head``'s mounting error (None for the reference head or when not estimated)."""
        if head == 0 or not self.mounted:
            return None
        start = 6 + self.n_cal + 3 * (head - 1)
        return slice(start, start + 3)

    @property
    def n_mount(self) -> int:
        return 3 * (len(self.heads) - 1) if self.mounted else 0

    @property
    def dt(self) -> int | None:
        return 6 + self.n_cal + self.n_mount if self.time_offset else None

    @property
    def n(self) -> int:
        return 6 + self.n_cal + self.n_mount + (1 if self.time_offset else 0)

    @property
    def n_param(self) -> int:
        """Dimension of the parameter vector p = (b, k, phi, dt) (the state without the attitude)."""
        return self.n - 3

    def names(self) -> list[str]:
        names = ["theta_x", "theta_y", "theta_z", "bias_x", "bias_y", "bias_z"]
        names += [(SCALE_NAMES + MISALIGNMENT_NAMES)[i] for i in self.calibration]
        if self.mounted:
            names += [f"mount_{h}_{a}" for h in self.heads[1:] for a in "xyz"]
        if self.time_offset:
            names.append("time_offset")
        return names

    def prior_sigmas(self, s: DefinitiveSettings) -> FloatArray:
        sig = [s.attitude_sigma_rad] * 3 + [s.bias_sigma_rad_s] * 3
        sig += [s.scale_factor_sigma if i < 3 else s.misalignment_sigma_rad for i in self.calibration]
        sig += [s.head_mounting_sigma_rad] * self.n_mount
        if self.time_offset:
            sig.append(s.time_offset_sigma_s)
        return np.asarray(sig, dtype=np.float64)


def layout_for(heads: tuple[str, ...], s: DefinitiveSettings) -> StateLayout:
    cal = (tuple(range(3)) if s.estimate_scale_factors else ()) + (tuple(range(3, 9)) if s.estimate_misalignment
                                                                      else ())
    return StateLayout(heads=heads, calibration=cal, mounted=s.estimate_head_mounting and len(heads) > 1,
                       time_offset=s.estimate_time_offset)


def k_matrix(k: FloatArray, layout: StateLayout) -> FloatArray:
    """K (3, 3) from the estimated calibration entries k (n_cal,) (entries not estimated are 0)."""
    out = np.zeros((3, 3))
    for value, i in zip(k, layout.calibration, strict=True):
        out[K_ENTRIES[i]] = value
    return out


def misalignment_parts(K: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(delta, n) of I + K = R_delta S (polar decomposition, R_delta a rotation, S symmetric positive):
    delta the rotation vector of R_delta (the triad's rotation, q_{G_true G} as 000's misalignment) and n the
    off-diagonal of S (xy, xz, yz: the non-orthogonality). To first order delta is the antisymmetric and n the
    symmetric part of K's off-diagonal; the polar factor keeps delta exact when the scale factors are not
    small against 1 (000: (1 + m) S^Delta = R_Delta (1 + m))."""
    from scipy.linalg import polar

    from processing.attitude.rotations import dcm_to_quat, quat_to_rotvec

    rot, sym = polar(np.eye(3) + K)
    return quat_to_rotvec(dcm_to_quat(rot)), np.array([sym[0, 1], sym[0, 2], sym[1, 2]])


def misalignment_jacobian() -> FloatArray:
    """(6, 6) linear map from the 6 misalignment parameters (MISALIGNMENT_NAMES order) to (delta, n)."""
    # parameters: K_xy, K_xz, K_yx, K_yz, K_zx, K_zy
    return 0.5 * np.array([
        [0, 0, 0, -1, 0, 1],   # delta_x = (K_zy - K_yz)/2
        [0, 1, 0, 0, -1, 0],   # delta_y = (K_xz - K_zx)/2
        [-1, 0, 1, 0, 0, 0],   # delta_z = (K_yx - K_xy)/2
        [1, 0, 1, 0, 0, 0],    # n_xy
        [0, 1, 0, 0, 1, 0],    # n_xz
        [0, 0, 0, 1, 0, 1],    # n_yz
    ], dtype=np.float64)
