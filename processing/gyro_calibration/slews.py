"""Slews in a drift-observer run (000): where the correction was off and resumed, how far the attitude
turned, and the error at the resumed sample against its bound.

Times float64 seconds; angles rad, rates rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from processing.gyro_calibration.drift_observer import MODE_PREDICTED, DriftObserverResult, slew_error_bound
from processing.signal.gyro_integration import IntervalRotations

__all__ = ["SlewReport", "slew_report"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SlewReport:
    """Slews (runs of samples with the correction off), each ended by a resumed correction.

    start_s, end_s (P,): last corrected sample before and the resumed sample after [s]; rotation_angle_rad
    (P,): integral of |w| over the slew; peak_rate_rad_s (P,); end_error_rad (P,): |innovation| at the
    resumed sample (attitude error of the predicted estimate plus star-tracker noise);
    bound_rad (P,): :func:`processing.gyro_calibration.drift_observer.slew_error_bound` with the 3-sigma
    calibration errors.
    """

    start_s: FloatArray
    end_s: FloatArray
    rotation_angle_rad: FloatArray
    peak_rate_rad_s: FloatArray
    end_error_rad: FloatArray
    bound_rad: FloatArray


def slew_report(obs: DriftObserverResult, rot: IntervalRotations, bound_terms: dict[str, float]) -> SlewReport:
    """Slews of an observer run (correction off, then resumed) from its interval rotations, with
    :func:`processing.gyro_calibration.drift_observer.slew_error_bound` of the given error terms."""
    mode = obs.mode
    resumed = np.flatnonzero((mode[1:] != MODE_PREDICTED) & (mode[:-1] == MODE_PREDICTED)) + 1
    starts, ends, angles, peaks, errors = [], [], [], [], []
    for k in resumed.tolist():  # one iteration per slew
        j = k - 1
        while j > 0 and mode[j] == MODE_PREDICTED:
            j -= 1
        starts.append(obs.t_s[j])
        ends.append(obs.t_s[k])
        angles.append(float(np.sum(np.linalg.norm(rot.rotvec_rad[j:k], axis=-1))))
        peaks.append(float(np.max(rot.max_rate_rad_s[j:k])))
        errors.append(float(np.linalg.norm(obs.innovation_rad[k])))
    s, e, th = np.asarray(starts), np.asarray(ends), np.asarray(angles)
    bound = slew_error_bound(e - s, th, **bound_terms)
    return SlewReport(start_s=s, end_s=e, rotation_angle_rad=th, peak_rate_rad_s=np.asarray(peaks),
                      end_error_rad=np.asarray(errors), bound_rad=np.asarray(bound, dtype=float))
