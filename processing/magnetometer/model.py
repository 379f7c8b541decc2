"""The magnetometer error model and its inverse (the correction applied to telemetry).

Model (frame M, nT; the convention of Alonso & Shuster 2002, "TWOSTEP", with a magnetorquer term):

    B_meas = (I + D) B_true + b + C mu_B + n

- D (3, 3) SYMMETRIC: diagonal D_xx, D_yy, D_zz = scale-factor errors (scale factor 1 + D_ii) and the
  off-diagonal D_xy, D_xz, D_yz = non-orthogonality (axis i leans towards axis j by D_ij rad, so the
  angle between the two axes differs from 90 deg by 2 D_ij). An antisymmetric part of I + D would be a
  rotation of the sensor, which |B| cannot see: it belongs to the mounting q_BM, not to D.
- b (3,) bias [nT]; C (3, 3) magnetorquer coupling [nT per A m^2], mu_B the commanded dipole (body
  frame, A m^2) held at the sample time; n the sensor noise.

Correction: B_true_est = (I + D)^-1 (B_meas - b - C mu_B).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["OFF_DIAGONAL", "MagnetometerErrors", "d_matrix"]

OFF_DIAGONAL: tuple[tuple[int, int], ...] = ((0, 1), (0, 2), (1, 2))
"""Index pairs of the three non-orthogonality elements, in the order (D_xy, D_xz, D_yz)."""


def d_matrix(scale_factor_errors: ArrayLike, non_orthogonality_rad: ArrayLike) -> NDArray[np.float64]:
    """Symmetric D (3, 3) from the scale-factor errors (D_xx, D_yy, D_zz) and the non-orthogonality
    (D_xy, D_xz, D_yz)."""
    s = np.asarray(scale_factor_errors, dtype=np.float64)
    o = np.asarray(non_orthogonality_rad, dtype=np.float64)
    if s.shape != (3,) or o.shape != (3,):
        raise ValueError(f"scale_factor_errors and non_orthogonality_rad must have shape (3,), got {s.shape}, "
                         f"{o.shape}")
    D = np.diag(s)
    for (i, j), v in zip(OFF_DIAGONAL, o, strict=True):
        D[i, j] = D[j, i] = v
    return D


@dataclass(frozen=True)
class MagnetometerErrors:
    """bias_nT (3,), D (3, 3) symmetric, coupling_nT_per_A_m2 (3, 3) (zeros: none). See the module docstring."""

    bias_nT: NDArray[np.float64]
    D: NDArray[np.float64]
    coupling_nT_per_A_m2: NDArray[np.float64]

    @classmethod
    def from_components(cls, bias_nT: ArrayLike = (0.0, 0.0, 0.0), scale_factor_errors: ArrayLike = (0.0, 0.0, 0.0),
                        non_orthogonality_rad: ArrayLike = (0.0, 0.0, 0.0),
                        coupling_nT_per_A_m2: ArrayLike | None = None) -> MagnetometerErrors:
        b = np.asarray(bias_nT, dtype=np.float64)
        C = np.zeros((3, 3)) if coupling_nT_per_A_m2 is None else np.asarray(coupling_nT_per_A_m2, dtype=np.float64)
        if b.shape != (3,) or C.shape != (3, 3):
            raise ValueError(f"bias_nT must have shape (3,) and the coupling (3, 3), got {b.shape}, {C.shape}")
        D = d_matrix(scale_factor_errors, non_orthogonality_rad)
        if np.linalg.det(np.eye(3) + D) <= 0.1:
            raise ValueError("I + D must be well invertible (scale-factor errors and non-orthogonality far below 1)")
        return cls(b, D, C)

    @property
    def scale_factor_errors(self) -> NDArray[np.float64]:
        return np.diag(self.D).copy()

    @property
    def non_orthogonality_rad(self) -> NDArray[np.float64]:
        return np.array([self.D[i, j] for i, j in OFF_DIAGONAL])

    @property
    def is_zero(self) -> bool:
        return not (np.any(self.bias_nT) or np.any(self.D) or np.any(self.coupling_nT_per_A_m2))

    def measure(self, B_true_M_nT: ArrayLike, mu_B_A_m2: ArrayLike | None = None) -> NDArray[np.float64]:
        """Noise-free B_meas (N, 3) nT from the true field B_true_M_nT (N, 3) nT and the dipole mu_B_A_m2 (N, 3)."""
        B = np.asarray(B_true_M_nT, dtype=np.float64)
        out = np.einsum("ij,kj->ki", np.eye(3) + self.D, B) + self.bias_nT  # einsum: no threaded BLAS
        if mu_B_A_m2 is not None:
            out = out + np.einsum("ij,kj->ki", self.coupling_nT_per_A_m2, np.asarray(mu_B_A_m2, dtype=np.float64))
        return np.asarray(out, dtype=np.float64)

    def correct(self, B_meas_M_nT: ArrayLike, mu_B_A_m2: ArrayLike | None = None) -> NDArray[np.float64]:
        """B_true_est = (I + D)^-1 (B_meas - b - C mu_B), (N, 3) nT; mu None: no coupling term."""
        y = np.asarray(B_meas_M_nT, dtype=np.float64) - self.bias_nT
        if mu_B_A_m2 is not None:
            y = y - np.einsum("ij,kj->ki", self.coupling_nT_per_A_m2, np.asarray(mu_B_A_m2, dtype=np.float64))
        return np.asarray(np.einsum("ij,kj->ki", np.linalg.inv(np.eye(3) + self.D), y), dtype=np.float64)
