"""Side by side: the definitive attitude against the papers' estimators on the same data (read-only use of
processing.gyro_calibration).

- ``gyro_bias_fit`` (003 §2): constant offsets and initial attitude by Gauss-Newton, in the reference head's
  frame R (as the gyro_bias_fit job: q_RG = q_SB o q_BG, further heads through q_RS). Compared: the body
  bias b_B = -R(q_BR) Delta with its honest sigma against the smoothed bias history's window mean, and the
  fitted attitude q_IB = q_IR o q_BR^-1 at the star-tracker samples against the smoothed one (rms per body
  axis). Needs gyro rates.
- ``alignment_calibration`` (000): drift, misalignment and scale factor of the gyro against the reference
  head (processing.gyro_calibration.calibration.calibrate_gyro with its default settings, increments or
  rates integrated). Compared: the misalignment rotation rotvec(q_GS o q_GS,nominal^-1) (gyro axes) against
  the antisymmetric part of K, the single scale factor m against each of our three, the drift at the end
  of the window against our bias there.

Each row carries both values, both sigmas and the difference over the combined sigma sqrt(s1² + s2²).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from processing.attitude import rotations
from processing.definitive.estimate import DefinitiveResult, StarTrackerHead
from processing.definitive.gyro import GyroSteps
from processing.definitive.model import K_ENTRIES, misalignment_jacobian, misalignment_parts
from processing.units import NS_PER_S


@dataclass(frozen=True)
class ComparisonRow:
    quantity: str
    axis: str
    unit: str
    ours: float | None
    ours_sigma: float | None
    theirs: float | None
    theirs_sigma: float | None

    @property
    def normalised_difference(self) -> float | None:
        vals = (self.ours, self.ours_sigma, self.theirs, self.theirs_sigma)
        if any(v is None or not np.isfinite(v) for v in vals):
            return None
        assert self.ours is not None and self.theirs is not None
        comb = float(np.hypot(self.ours_sigma or 0.0, self.theirs_sigma or 0.0))
        return (self.ours - self.theirs) / comb if comb > 0 else None

    def as_dict(self) -> dict[str, object]:
        return {"quantity": self.quantity, "axis": self.axis, "unit": self.unit, "ours": self.ours,
                "ours_sigma": self.ours_sigma, "theirs": self.theirs, "theirs_sigma": self.theirs_sigma,
                "difference_over_combined_sigma": self.normalised_difference}


def _f(x: object) -> float | None:
    v = float(x)  # type: ignore[arg-type]
    return v if np.isfinite(v) else None


def compare_gyro_bias_fit(result: DefinitiveResult, steps: GyroSteps, heads: list[StarTrackerHead],
                          q_BG: np.ndarray) -> dict[str, object]:
    """Run the 003 §2 fit on the same window and compare (module docstring)."""
    from processing.gyro_calibration.bias_fit import fit_gyro_bias

    if steps.kind != "rates":
        return {"available": False, "reason": "gyro_bias_fit needs gyro rates; the window has increments"}
    epoch = int(steps.sample_t_ns[0])
    t_g = (steps.sample_t_ns - epoch).astype(np.float64) / NS_PER_S
    q_SB_ref = rotations.quat_conjugate(heads[0].q_BS)
    t_st = np.concatenate([h.time_tai_ns for h in heads])
    q_IS = np.concatenate([h.q_IS for h in heads])
    idx = np.concatenate([np.full(h.time_tai_ns.size, j) for j, h in enumerate(heads)])
    keep = (t_st >= steps.sample_t_ns[0]) & (t_st <= steps.sample_t_ns[-1])
    q_RS = np.stack([rotations.quat_multiply(q_SB_ref, h.q_BS) for h in heads])[idx[keep]]
    fit = fit_gyro_bias(t_g, steps.rate_samples_G, (t_st[keep] - epoch) / NS_PER_S, q_IS[keep], q_RS=q_RS,
                        sensor_index=idx[keep], q_RG=rotations.quat_multiply(q_SB_ref, q_BG))
    q_BR = heads[0].q_BS
    r_br = rotations.quat_to_dcm(rotations.quat_multiply(q_BG, rotations.quat_conjugate(fit.q_RG)))
    b_theirs = -r_br @ fit.delta_R_rad_s
    s_theirs = np.sqrt(np.diag(r_br @ fit.covariance[3:6, 3:6] @ r_br.T))
    r_bg = rotations.quat_to_dcm(q_BG)
    b_ours = result.bias_G_rad_s @ r_bg.T
    cov_b = np.einsum("ij,kjl,ml->kim", r_bg, result.covariance[:, 3:6, 3:6], r_bg)
    rows = [ComparisonRow("gyro bias (window mean, body)", a, "rad/s", _f(np.mean(b_ours[:, i])),
                          _f(np.sqrt(np.mean(cov_b[:, i, i]))), _f(b_theirs[i]), _f(s_theirs[i]))
            for i, a in enumerate("xyz")]
    q_IB_fit = rotations.quat_multiply(fit.q_IR_model, rotations.quat_conjugate(q_BR))  # input order
    t_fit = t_st[keep]
    at = np.minimum(np.searchsorted(result.time_tai_ns, t_fit), result.time_tai_ns.size - 1)
    ok = result.time_tai_ns[at] == t_fit
    d = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(result.q_IB[at[ok]]),
                                                         q_IB_fit[ok]))
    return {"available": True, "rows": [r.as_dict() for r in rows],
            "attitude_rms_difference_rad": np.sqrt(np.mean(d**2, axis=0)).tolist(),
            "gyro_bias_fit_residual_rms_rad": fit.residual_rms_rad[0].tolist(),
            "converged": bool(fit.converged), "q_IB_gyro_bias_fit": q_IB_fit[ok], "time_tai_ns": t_fit[ok]}


def compare_alignment(result: DefinitiveResult, steps: GyroSteps, heads: list[StarTrackerHead],
                      q_BG: np.ndarray) -> dict[str, object]:
    """Run the 000 calibration against the reference head and compare (module docstring)."""
    from processing.gyro_calibration.calibration import calibrate_gyro
    from processing.signal.two_pass_filter import increments_from_rates

    t0 = int(steps.t_ns[0])
    if steps.kind == "increments":
        t_end = (steps.sample_t_ns - t0).astype(np.float64) / NS_PER_S
        inc = steps.rate_samples_G * np.diff(np.concatenate([[0.0], t_end]))[:, None]
        interval = np.diff(np.concatenate([[0.0], t_end]))
    else:
        ts = (steps.sample_t_ns - t0).astype(np.float64) / NS_PER_S
        t_end, inc, interval = increments_from_rates(ts, steps.rate_samples_G)
    head = heads[0]
    q_GS_nom = rotations.quat_canonical(rotations.quat_multiply(rotations.quat_conjugate(q_BG), head.q_BS))
    cal = calibrate_gyro(t_end, inc, interval, (head.time_tai_ns - t0).astype(np.float64) / NS_PER_S, head.q_IS,
                         q_GS_nominal=q_GS_nom)
    est = cal.alignment
    theirs_mis = rotations.quat_to_rotvec(rotations.quat_multiply(est.q_GS, rotations.quat_conjugate(q_GS_nom)))
    lay = result.layout
    rows: list[ComparisonRow] = []
    cal_idx = {entry: j for j, entry in enumerate(lay.calibration)}
    cov = result.parameter_covariance[:lay.n_cal, :lay.n_cal]
    if all(e in cal_idx for e in range(3, 9)):
        sel = [cal_idx[e] for e in range(3, 9)]
        J = misalignment_jacobian()
        delta, _ = misalignment_parts(result.K)
        cd = J @ cov[np.ix_(sel, sel)] @ J.T
        for i, a in enumerate("xyz"):
            rows.append(ComparisonRow("misalignment rotation (gyro axes)", a, "rad", _f(delta[i]),
                                      _f(np.sqrt(cd[i, i])), _f(theirs_mis[i]) if est.observable_axes[i] else None,
                                      _f(est.misalignment_sigma_rad[i])))
    for i, a in enumerate("xyz"):
        if i in cal_idx:
            sf_ok = bool(np.all(est.scale_factor_observable))  # undetermined by 000: nothing to compare
            rows.append(ComparisonRow("scale factor error", a, "", _f(result.K[K_ENTRIES[i]]),
                                      _f(np.sqrt(cov[cal_idx[i], cal_idx[i]])),
                                      _f(est.scale_factor_error) if sf_ok else None,
                                      _f(est.scale_factor_sigma) if sf_ok else None))
    t_last = t0 + int(round(cal.observer.t_s[-1] * NS_PER_S))
    j = min(int(np.searchsorted(result.time_tai_ns, t_last)), result.time_tai_ns.size - 1)
    for i, a in enumerate("xyz"):
        rows.append(ComparisonRow("gyro drift at the end (gyro axes)", a, "rad/s", _f(result.bias_G_rad_s[j, i]),
                                  _f(result.bias_sigma_G_rad_s[j, i]),
                                  _f(cal.drift_rad_s[i]) if est.drift_observable[i] else None,
                                  _f(cal.drift_sigma_rad_s[i]) if est.drift_observable[i] else None))
    return {"available": True, "reference_sensor": head.name, "rows": [r.as_dict() for r in rows],
            "converged": bool(cal.converged)}
