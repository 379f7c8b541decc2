"""Smooth truth model of a spacecraft held in orbital orientation: circular orbit + pitch/yaw/roll.

Used by the scenario simulators (seed 003). Everything is analytic, so the attitude and its body
rate are exactly consistent at any time (no numerical differentiation):

- orbit: two-body circular orbit (processing.orbits.two_body.circular_orbit_state with zero node rate), in
  the inertial frame I (GCRS for the simulators);
- orbital frame O of 003 §1.6 (processing.frames.orbital.q_IO_003): axis 3 radial, axis 2 along
  r x v, axis 1 transversal. On a two-body orbit the plane is fixed and O turns about its axis 2 at
  |r x v| / |r|^2, so w_IO (rate of O relative to I, in O) = (0, |r x v| / |r|^2, 0);
- attitude relative to O: pitch alpha, yaw beta, roll gamma (003 §1.6: alpha about axis 2, then beta
  about the new axis 3, then gamma about the resulting axis 1), q_OB = q_y(alpha) o q_z(beta) o
  q_x(gamma) (processing.attitude.rotations.quat_from_pitch_yaw_roll); each angle is a sum of sinusoids
  (:class:`SinusoidSeries`), evaluated with its exact time derivative;
- q_IB = q_IO o q_OB and w_B = dcm_BO w_IO + w_OB, where the rate of B relative to O, in B, of the
  2-3-1 sequence is (derivation: w_OB = gamma' e1 + beta' R1(gamma)^T e3 + alpha' R1(gamma)^T
  R3(beta)^T e2, each rate about its own axis written in B)

      w_OB = (gamma' + alpha' sin beta,
              beta' sin gamma + alpha' cos gamma cos beta,
              beta' cos gamma - alpha' sin gamma cos beta).

The kinematics q_IB' = 1/2 q_IB o w_B then hold to rounding (checked by integration in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.frames.orbital import q_IO_003
from processing.orbits.two_body import circular_orbit_state


@dataclass(frozen=True)
class SinusoidSeries:
    """x(t) = mean_rad + sum_k amplitudes_rad[k] sin(2 pi t / periods_s[k] + phases_rad[k]) [rad].

    |x - mean_rad| <= sum(|amplitudes_rad|) for every t.
    """

    mean_rad: float
    amplitudes_rad: tuple[float, ...]
    periods_s: tuple[float, ...]
    phases_rad: tuple[float, ...]

    def __post_init__(self) -> None:
        n = len(self.amplitudes_rad)
        if len(self.periods_s) != n or len(self.phases_rad) != n:
            raise ValueError(
                f"amplitudes, periods and phases must have equal lengths, got {n}, "
                f"{len(self.periods_s)}, {len(self.phases_rad)}"
            )
        if any(p <= 0 for p in self.periods_s):
            raise ValueError(f"periods must be > 0 s, got {self.periods_s}")

    def value_and_rate(self, t_s: ArrayLike) -> tuple[NDArray, NDArray]:
        """x(t) [rad] and dx/dt [rad/s] at t_s (...) seconds; both of shape t_s.shape."""
        t = np.asarray(t_s, dtype=float)[..., None]
        amp = np.asarray(self.amplitudes_rad, dtype=float)
        omega = 2.0 * np.pi / np.asarray(self.periods_s, dtype=float)
        arg = omega * t + np.asarray(self.phases_rad, dtype=float)
        x = self.mean_rad + np.sum(amp * np.sin(arg), axis=-1)
        x_dot = np.sum(amp * omega * np.cos(arg), axis=-1)
        return x, x_dot


def body_rate_from_pitch_yaw_roll(
    pitch_rad: ArrayLike,
    yaw_rad: ArrayLike,
    roll_rad: ArrayLike,
    pitch_rate_rad_s: ArrayLike,
    yaw_rate_rad_s: ArrayLike,
    roll_rate_rad_s: ArrayLike,
) -> NDArray:
    """Angular velocity of B relative to O, in B coordinates (..., 3) [rad/s], of the 003 angles.

    Angles and their rates (...) broadcast; the sequence is that of
    processing.attitude.rotations.quat_from_pitch_yaw_roll (003 §1.6): satisfies
    q_OB' = 1/2 q_OB o w_OB for q_OB = quat_from_pitch_yaw_roll(pitch, yaw, roll).
    """
    a_dot = np.asarray(pitch_rate_rad_s, dtype=float)
    b_dot = np.asarray(yaw_rate_rad_s, dtype=float)
    g_dot = np.asarray(roll_rate_rad_s, dtype=float)
    sb, cb = np.sin(yaw_rad), np.cos(yaw_rad)
    sg, cg = np.sin(roll_rad), np.cos(roll_rad)
    return np.stack(
        np.broadcast_arrays(g_dot + a_dot * sb, b_dot * sg + a_dot * cg * cb, b_dot * cg - a_dot * sg * cb),
        axis=-1,
    )


@dataclass(frozen=True)
class AttitudeState:
    """Truth at a set of times (all arrays with leading shape t_s.shape).

    r_I, v_I [m, m/s]; q_IO, q_OB, q_IB canonical scalar-first; w_B [rad/s] rate of B w.r.t. I in B;
    pitch_rad, yaw_rad, roll_rad and their rates [rad, rad/s] (003 §1.6).
    """

    r_I: NDArray
    v_I: NDArray
    q_IO: NDArray
    q_OB: NDArray
    q_IB: NDArray
    w_B: NDArray
    pitch_rad: NDArray
    yaw_rad: NDArray
    roll_rad: NDArray
    pitch_rate_rad_s: NDArray
    yaw_rate_rad_s: NDArray
    roll_rate_rad_s: NDArray


@dataclass(frozen=True)
class OrbitalAttitudeModel:
    """Circular two-body orbit plus pitch/yaw/roll series; evaluate at any time since the epoch.

    a_m, inc_rad, raan_rad, u0_rad: orbit radius and elements at t = 0 (processing.orbits.two_body).
    pitch, yaw, roll: angle series (003 §1.6 angles of B relative to the 003 orbital frame).
    """

    a_m: float
    inc_rad: float
    raan_rad: float
    u0_rad: float
    pitch: SinusoidSeries
    yaw: SinusoidSeries
    roll: SinusoidSeries

    def orbit(self, t_s: ArrayLike) -> tuple[NDArray, NDArray]:
        """r_I, v_I (..., 3) [m, m/s] at t_s (...) seconds since the epoch."""
        return circular_orbit_state(t_s, self.a_m, self.inc_rad, self.raan_rad, self.u0_rad)

    def evaluate(self, t_s: ArrayLike) -> AttitudeState:
        """Orbit, orbital frame, attitude and body rate at t_s (...) seconds since the epoch."""
        r_I, v_I = self.orbit(t_s)
        q_IO = q_IO_003(r_I, v_I)
        pitch, pitch_dot = self.pitch.value_and_rate(t_s)
        yaw, yaw_dot = self.yaw.value_and_rate(t_s)
        roll, roll_dot = self.roll.value_and_rate(t_s)
        q_OB = rotations.quat_from_pitch_yaw_roll(pitch, yaw, roll)
        q_IB = rotations.quat_canonical(rotations.quat_multiply(q_IO, q_OB))
        h = np.linalg.norm(np.cross(r_I, v_I), axis=-1)
        orbit_rate = h / np.sum(r_I * r_I, axis=-1)  # rad/s about O axis 2 (two-body)
        w_IO_O = np.stack([np.zeros_like(orbit_rate), orbit_rate, np.zeros_like(orbit_rate)], axis=-1)
        w_IO_B = rotations.quat_rotate(rotations.quat_conjugate(q_OB), w_IO_O)
        w_B = w_IO_B + body_rate_from_pitch_yaw_roll(pitch, yaw, roll, pitch_dot, yaw_dot, roll_dot)
        return AttitudeState(
            r_I=r_I,
            v_I=v_I,
            q_IO=q_IO,
            q_OB=q_OB,
            q_IB=q_IB,
            w_B=w_B,
            pitch_rad=pitch,
            yaw_rad=yaw,
            roll_rad=roll,
            pitch_rate_rad_s=pitch_dot,
            yaw_rate_rad_s=yaw_dot,
            roll_rate_rad_s=roll_dot,
        )
