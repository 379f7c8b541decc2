"""The declared result (summary) schema of each job type: the top-level keys with their JSON types.

These are the OpenAPI ``<Type>Summary`` schemas (app/api/schemas.py) and what a client may rely on;
``tests/app/test_openapi.py`` runs every job type on simulated data and checks that each summary key is
declared here and validates. Numbers are nullable everywhere: a value the data do not determine is
``null`` (with ``*_observable: false``) and non-finite numbers are stored as ``null``. Nested objects are
typed ``object`` (their keys are documented in the README and the report). A job type may instead set
``JobType.result_model``; one that declares nothing gets :class:`Summary` (warnings typed, keys open).
"""

from __future__ import annotations

import enum
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel, ConfigDict, Field, create_model

from processing.tasks import WARNING_CODES

if TYPE_CHECKING:
    from app.jobs.registry import JobType

WarningCode = enum.Enum("WarningCode", {code: code for code in WARNING_CODES}, type=str)  # type: ignore[misc]
WarningCode.__doc__ = "the stable warning codes (README, Warnings)"


class WarningOut(BaseModel):
    """A result's statement about itself (processing.tasks.ResultWarning)."""

    code: WarningCode
    message: str
    evidence: dict[str, Any] = Field(default_factory=dict)


class Summary(BaseModel):
    """A job summary: ``warnings`` first, then the job type's keys (units in their names)."""

    model_config = ConfigDict(extra="allow")
    warnings: list[WarningOut] = Field(default_factory=list)
    outputs: dict[str, Any] | None = Field(None, description=(
        "present when the job's artifacts were bounded (app.jobs.outputs): parquet_only (tables whose CSV is made "
        "on request), truncated ({table: {rows, stored_rows}}), omitted (artifact names left out), limits"))


NUM = float | None
INT = int | None
STR = str | None
BOOL = bool | None
VEC = list[float | None] | None  # per axis / component
MAT = list[list[float | None]] | None
BOOLS = list[bool | None] | None
INTS = list[int | None] | None
STRS = list[str] | None
OBJ = dict[str, Any] | None
OBJS = list[dict[str, Any]] | None
LIST = list[Any] | None
STAT = dict[str, float | None] | None  # {mean, std, min, max, ...}


def _summary(job_type: str, **fields: Any) -> type[BaseModel]:
    camel = "".join(part.capitalize() for part in job_type.split("_"))
    model: type[BaseModel] = create_model(  # type: ignore[call-overload]
        f"{camel}Summary", __base__=Summary, __doc__=f"the summary of a {job_type} job",
        **{k: (v, None) for k, v in fields.items()})
    return model


_DECLARED = (
    _summary("telemetry_coverage", window_start_tai_ns=INT, window_end_tai_ns=INT, gap_factor=NUM, n_streams=INT,
             n_gaps=INT, streams=OBJS, gaps_in_summary=STR),
    _summary("executor_check", duration_s=NUM, worker_pid=INT),
    _summary("star_tracker_accuracy", sensor=STR, sigma_arcsec=VEC, sigma_smoothing_arcsec=VEC,
             sigma_robust_arcsec=VEC, sigma_smoothing_robust_arcsec=VEC, sigma_eq2_arcsec=VEC, motion_rms_arcsec=VEC,
             axes=STRS, harmonics=INT, harmonics_per_segment=INTS, harmonics_mode=STR, cutoff_hz=NUM, n_samples=INT,
             n_segments=INT, sample_period_s=NUM, gyro_used=BOOL, spectral_lines=OBJS, gyro_rate_rms_diff_arcsec_s=VEC,
             gyro_rate_rms_diff_expected_arcsec_s=VEC, gyro_offset_arcsec_s=VEC, gyro_noise_sigma_arcsec_s=VEC,
             gyro_smoothing_sigma_arcsec_s=VEC, gyro_axes=STRS, n_outliers=INT, outlier_threshold_sigma=NUM,
             outlier_scale_arcsec=VEC, outliers=OBJS, sigma_ci95_arcsec=MAT, sigma_dof=VEC,
             sigma_above_cutoff_arcsec=VEC, sigma_lower_bound_arcsec=VEC, whiteness_p_value=VEC,
             whiteness_power_ratio=VEC, residuals_white=BOOL, gyro_lines=OBJS, plausibility=OBJ, gyro_coverage=OBJ),
    _summary("gyro_bias_fit", gyro_bias_rad_s=VEC, gyro_bias_sigma_rad_s=VEC, gyro_bias_sigma_constant_rad_s=VEC,
             gyro_bias_sigma_paper_rad_s=VEC, delta_sensor_arcsec_s=VEC, delta_sensor_sigma_arcsec_s=VEC,
             delta_sensor_sigma_paper_arcsec_s=VEC, delta_body_arcsec_s=VEC, delta_body_sigma_arcsec_s=VEC,
             offset_constancy=OBJ, time_offset_s=NUM, time_offset_sigma_s=NUM, time_offset_observable=BOOL,
             time_offset_corrected_s=NUM, quaternion_convention=STR, initial_mrp=VEC, initial_mrp_sigma=VEC,
             initial_mrp_sigma_paper=VEC, initial_time=STR, initial_time_tai_ns=INT, initial_q_IS=VEC,
             initial_q_IB=VEC, sigma_unit_weight=NUM, residual_rms_arcsec=VEC, residual_rms_gyro_arcsec=VEC,
             residual_consistency=VEC, star_tracker_sigma_arcsec=VEC, iterations=INT, converged=BOOL, status=STR,
             scheme=INT, use_smoothed_rates=BOOL, smoothing_harmonics=INT, weights=VEC, gyro_arw_rad_sqrt_s=VEC,
             gyro_arw_source=STR, reference_sensor=STR, sensors=OBJ, n_star_tracker_samples=INT, n_gyro_samples=INT,
             parameter_names=STRS, covariance=MAT, covariance_paper=MAT, condition_number=NUM, mounting=OBJ,
             subintervals=OBJS),
    _summary("orbital_attitude", pitch_deg=STAT, yaw_deg=STAT, roll_deg=STAT, inertial_frame=STR, orbital_frame=STR,
             eop=OBJ, sensor=STR, q_BS=VEC, smoothing=BOOL, smoothing_frame=STR, trend_degree=INT, raw=OBJ,
             first_tai_ns=INT, last_tai_ns=INT, n_samples=INT, n_dropped_outside_gnss=INT, gnss_fit=OBJ,
             smoothing_segments=OBJS, smoothing_residual_rms_arcsec=VEC, ascending_nodes_tai_ns=INTS,
             angles_by_sequence=OBJ, euler_sequence=STR, euler_sequence_description=STR, orbit_frame_sigma_arcsec=OBJ,
             angle_sigma_arcsec=OBJ, angle_sigma_note=STR, manoeuvres=OBJ, n_smoothing_segments=INT,
             n_ascending_nodes=INT),
    _summary("gyroless_ekf", filter=STR, smoother=BOOL, n_steps=INT, step_s=NUM, start_tai_ns=INT, end_tai_ns=INT,
             converged=BOOL, time_to_converge_s=NUM, nis_mean=NUM, nis_dof_mean=NUM, nis_mean_bounds_95=VEC,
             nis_mean_in_bounds=BOOL, nis_fraction_in_95=NUM, whiteness=OBJ, innovation_rms_deg=OBJ, roll_deg=STAT,
             pitch_deg=STAT, yaw_deg=STAT, attitude_sigma_deg=OBJ, rate_sigma_deg_s=OBJ, disturbance_N_m=OBJ,
             sun_used_fraction=NUM, sun_outages=OBJS, counts=OBJ, artifacts=OBJ, consistency=OBJ, process_noise=OBJ,
             magnetometer_bias=OBJ, field_error_O_nT=OBJ),
    _summary("alignment_calibration", sensor=STR, gyro_stream=STR, n_star_tracker_samples=INT, n_gyro_samples=INT,
             window_start_tai_ns=INT, window_end_tai_ns=INT, misalignment_rad=VEC, misalignment_arcsec=VEC,
             misalignment_sigma_rad=VEC, misalignment_sigma_arcsec=VEC, misalignment_quaternion=VEC,
             misalignment_observable=BOOLS, q_GS=VEC, q_GS_nominal=VEC, rate_spread_eigenvalues=VEC,
             scale_factor_error=NUM, scale_factor_error_sigma=NUM, scale_factor_error_percent=NUM, drift_rad_s=VEC,
             drift_arcsec_s=VEC, drift_frame=STR, drift_time_tai_ns=INT, drift_noise_rad_s=VEC,
             drift_convergence_s=NUM, drift_model=OBJ, alignment_drift_offset_rad_s=VEC, calibration_windows=INT,
             calibration_windows_found=INT, alignment_samples=INT, iterations=INT, converged=BOOL,
             iteration_history=OBJS, observer=OBJ, star_tracker_noise_arcsec=VEC, attitude_residual_rms_arcsec=VEC,
             n_slews=INT, slew_end_error_max_arcsec=NUM, slew_error_bound_max_arcsec=NUM, slew_bound_exceeded=INT,
             integration_error_max_arcsec=NUM, solver_disagreement_rad=NUM, calibration_complete=BOOL,
             calibration=OBJ, scale_factor_observable=BOOL, observability=OBJ, drift_sigma_rad_s=VEC,
             drift_sigma_arcsec_s=VEC, drift_observable=BOOLS, apparent_drift_rad_s=VEC, drift_correlation_time_s=VEC,
             plausibility=OBJ, time_offset_s=NUM, time_offset_sigma_s=NUM),
    _summary("data_screening", streams=OBJ, n_total=INT, n_rejected=INT, rejected_fraction=NUM, energy_model=STR,
             energy_reference=STR, navigation_data=STR, screened_streams=STRS, findings=OBJ),
    _summary("vector_attitude", method=STR, methods_used=OBJ, n_epochs=INT, n_attitude=INT, availability=NUM,
             vectors_available=OBJ, vectors_missing_reasons=OBJ, residuals=OBJ, bound99_deg_median=NUM,
             pitch_deg=STAT, yaw_deg=STAT, roll_deg=STAT, screened=BOOL, rejected_samples=OBJ, navigation_data=STR,
             orbital_frame=STR),
    _summary("reconstruction", stages_run=STRS, stages=OBJ, calibrations=OBJ),
    _summary("definitive_attitude", reference_sensor=STR, sensors=OBJ, gyro_stream=STR, n_epochs=INT,
             start_tai_ns=INT, end_tai_ns=INT, passes=INT, attitude_sigma_arcsec=OBJ, gyro_bias_rad_s=VEC,
             gyro_bias_sigma_rad_s=VEC, gyro_bias_observable=BOOLS, gyro_bias_frame=STR, gyro_bias_change_rad_s=VEC,
             calibration=OBJ, observability=OBJ, nis=OBJ, nees=OBJ, whiteness=OBJ, gyro_arw_rad_sqrt_s=VEC,
             gyro_arw_source=STR, bias_random_walk_rad_s_sqrt_s=NUM, max_second_order_rad=NUM, artifacts=OBJ,
             plausibility=OBJ),
    _summary("gyro_noise", source=STR, data=STR, rate_hz=NUM, n_samples=INT, period_s=NUM, angle_white_noise_rad=VEC,
             angle_white_noise_ci95_rad=MAT, angle_white_noise_observable=BOOLS, angle_random_walk_rad_sqrt_s=VEC,
             angle_random_walk_ci95_rad_sqrt_s=MAT, angle_random_walk_observable=BOOLS,
             angle_random_walk_deg_sqrt_h=VEC, bias_instability_rad_s=VEC, bias_instability_ci95_rad_s=MAT,
             bias_instability_observable=BOOLS, bias_instability_deg_h=VEC, rate_random_walk_rad_s_sqrt_s=VEC,
             rate_random_walk_ci95_rad_s_sqrt_s=MAT, rate_random_walk_observable=BOOLS, fit_chi2_per_dof=VEC,
             axes=STR, model=STR, artifacts=OBJ),
    _summary("magnetometer_calibration", sensor=STR, n_samples=INT, n_used=INT, sample_period_s=NUM, start_tai_ns=INT,
             end_tai_ns=INT, model=STR, bias_nT=VEC, bias_sigma_nT=VEC, bias_observable=BOOLS, scale_factors=VEC,
             scale_factor_errors=VEC, scale_factor_sigma=VEC, scale_factor_observable=BOOLS, non_orthogonality_rad=VEC,
             non_orthogonality_sigma_rad=VEC, non_orthogonality_observable=BOOLS, non_orthogonality_axes=STRS,
             residual_field_rms_before_nT=NUM, residual_field_rms_after_nT=NUM, residual_sigma_nT=NUM, iterations=INT,
             converged=BOOL, information_singular_values_relative=VEC, whiteness=OBJ, chi_square=OBJ,
             parameter_names=STRS, correlation=MAT, calibration_complete=BOOL, calibration=OBJ, artifacts=OBJ),
)
RESULTS: dict[str, type[BaseModel]] = {m.__name__: m for m in _DECLARED}


def summary_model(job_type: JobType) -> type[BaseModel]:
    """The declared summary model of a job type (``JobType.result_model``, else the one above, else generic)."""
    if job_type.result_model is not None:
        return job_type.result_model
    camel = "".join(part.capitalize() for part in job_type.name.split("_"))
    return RESULTS.get(f"{camel}Summary", Summary)
