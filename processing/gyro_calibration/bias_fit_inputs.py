"""Step 1 of the gyro offset fit (processing.gyro_calibration.bias_fit): the inputs checked, naming what is wrong,
and the problem set up in the reference frame R, sorted by star-tracker time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from processing.attitude import rotations
from processing.gyro_calibration.bias_fit_model import Problem

FloatArray = NDArray[np.float64]


class GyroBiasFitError(ValueError):
    """Bad input to the gyro offset fit: shapes, too few samples, no overlap of the two time grids."""


def _quat_rows(q: ArrayLike, m: int, name: str) -> FloatArray:
    a = np.asarray(q, dtype=np.float64)
    if a.shape == (4,):
        a = np.broadcast_to(a, (m, 4))
    if a.shape != (m, 4):
        raise GyroBiasFitError(f"{name} must have shape (4,) or ({m}, 4), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise GyroBiasFitError(f"{name} must be finite")
    return rotations.quat_normalize(a)


@dataclass(frozen=True)
class Prepared:
    """Step 1: the problem in R sorted by star-tracker time, the sort order, the sorted sensor index,
    the number of trackers, t0 (s, the gyro node at or before the first sample) and q_RG normalised."""

    pb: Problem
    order: NDArray[np.int64]
    sens: NDArray[np.int64]
    n_sensors: int
    t0: float
    q_rg: FloatArray


def prepare(
    t_gyro_s: ArrayLike,
    w_G: ArrayLike,
    t_st_s: ArrayLike,
    q_IS: ArrayLike,
    q_RG: ArrayLike,
    q_RS: ArrayLike | None,
    sensor_index: ArrayLike | None,
    weights: ArrayLike,
    scheme: int,
    mounting: bool,
) -> Prepared:
    """Step 1: check the inputs (:class:`GyroBiasFitError` naming what is wrong) and set up the problem."""
    tg = np.asarray(t_gyro_s, dtype=np.float64)
    wg = np.asarray(w_G, dtype=np.float64)
    if tg.ndim != 1 or tg.size < 2 or wg.shape != (tg.size, 3):
        raise GyroBiasFitError(f"need t_gyro_s (N,) and w_G (N, 3), N >= 2, got {tg.shape} and {wg.shape}")
    if not (np.all(np.isfinite(tg)) and np.all(np.isfinite(wg))):
        raise GyroBiasFitError("gyro times and rates must be finite")
    if not np.all(np.diff(tg) > 0):
        raise GyroBiasFitError("gyro times must be strictly increasing")
    ts = np.asarray(t_st_s, dtype=np.float64)
    if ts.ndim != 1:
        raise GyroBiasFitError(f"t_st_s must have shape (M,), got {ts.shape}")
    m = ts.size
    qm = np.asarray(q_IS, dtype=np.float64)
    if qm.shape != (m, 4) or not np.all(np.isfinite(qm)) or not np.all(np.isfinite(ts)):
        raise GyroBiasFitError(f"q_IS must be finite with shape ({m}, 4), got {qm.shape}")
    wts = np.asarray(weights, dtype=np.float64)
    if wts.shape != (3,) or not np.all(wts > 0) or not np.all(np.isfinite(wts)):
        raise GyroBiasFitError(f"weights must be 3 positive numbers, got {weights!r}")
    if scheme not in (1, 2):
        raise GyroBiasFitError(f"scheme must be 1 or 2, got {scheme!r}")
    n_par = 9 if mounting else 6
    if 3 * m <= n_par:
        raise GyroBiasFitError(f"need more than {n_par // 3} star-tracker samples, got {m}")
    if ts.min() < tg[0] or ts.max() > tg[-1]:
        raise GyroBiasFitError(
            f"star-tracker samples [{ts.min()}, {ts.max()}] s must lie within the gyro samples "
            f"[{tg[0]}, {tg[-1]}] s"
        )
    sens = np.zeros(m, dtype=np.int64) if sensor_index is None else np.asarray(sensor_index).astype(np.int64)
    if sens.shape != (m,) or (m and sens.min() < 0):
        raise GyroBiasFitError(f"sensor_index must be (M,) integers >= 0, got shape {sens.shape}")
    n_sensors = int(sens.max()) + 1 if m else 1
    q_rs = _quat_rows(np.array([1.0, 0.0, 0.0, 0.0]) if q_RS is None else q_RS, m, "q_RS")
    q_rg = rotations.quat_normalize(np.asarray(q_RG, dtype=np.float64))

    order = np.argsort(ts, kind="stable")
    ts, qm, q_rs, sens_sorted = ts[order], qm[order], q_rs[order], sens[order]
    k0 = int(np.searchsorted(tg, ts[0], side="right")) - 1
    k1 = max(int(np.searchsorted(tg, ts[-1], side="left")), k0 + 1)
    t0 = float(tg[k0])
    # (N, 3) in Fortran order: omega = w_R + Delta then is too, and the propagation's components-first (3, N)
    # view of it needs no transposing copy on every evaluation
    w_R = np.asfortranarray(rotations.quat_rotate(q_rg, wg[k0 : k1 + 1]))
    pb = Problem(
        t_g=tg[k0 : k1 + 1] - t0,
        w_R=w_R,
        t_st=ts - t0,
        q_meas=rotations.quat_normalize(qm),
        q_RS=q_rs,
        rot_RS_T=np.swapaxes(rotations.quat_to_dcm(q_rs), 1, 2),
        weights=wts,
        scheme=int(scheme),
        mounting=mounting,
    )
    return Prepared(pb, order, sens_sorted, n_sensors, t0, q_rg)
