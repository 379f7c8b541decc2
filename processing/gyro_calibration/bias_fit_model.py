"""The gyro offset fit's model and iteration (003 §2.1-2.3): residuals, Jacobian, Gauss-Newton.

Paper 003 (Avanesov et al., Keldysh preprint 74, 2010). In the reference star-tracker frame R the rates
w' = R(q_RG) w_G + Delta (eq. 5, optionally with the mounting correction exp(mu)) are integrated on the
gyro grid from q(t0) = p(z) (003 §2.2, processing.gyro_calibration.propagation); tracker j is modelled as
q(t) o q_RSj. The residuals (a0, a) = 1 - q_n^-1 o q(t_n) o q_RSj (eq. 6's a_{i,n}, sign of q_n such that
a0 is small) enter Phi = sum w_i a_{i,n}^2 (eq. 6); their derivatives with respect to x = (z, Delta[, mu])
follow from the pseudo-derivatives of eq. 7, da/dx_k = -vec(q_n^-1 o 1/2 q o psi_k o q_RSj), and give the
Gauss-Newton normal equations C dx = d of 003 §2.2 (:func:`normal_equations`), solved with scaled columns
and step halving by :func:`gauss_newton`. The covariances and the result are in
processing.gyro_calibration.bias_fit.

Times float64 seconds from t0; angles rad, rates rad/s; quaternions scalar first, Hamilton.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.gyro_calibration.propagation import Propagation, mrp_pseudo_derivatives, propagate

__all__ = [
    "SIGMA_FLOOR",
    "Evaluation",
    "GaussNewton",
    "Problem",
    "State",
    "cross_matrix",
    "evaluate",
    "gauss_newton",
    "initial_guess",
    "linear_step",
    "normal_equations",
    "scaled_inverse",
]

FloatArray = NDArray[np.float64]

SIGMA_FLOOR = 1e-12
"""Floor on sigma_w in the convergence test (noise-free data), in the units of a (half radians)."""


def cross_matrix(v: FloatArray) -> FloatArray:
    """[v x] (..., 3, 3) of vectors v (..., 3)."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def scaled_inverse(c: FloatArray) -> tuple[FloatArray, float]:
    """C^-1 via the correlation-scaled matrix, and the condition number of that scaled matrix."""
    s = 1.0 / np.sqrt(np.diag(c))
    cs = c * s[:, None] * s[None, :]
    cond = float(np.linalg.cond(cs))
    return np.linalg.inv(cs) * s[:, None] * s[None, :], cond


@dataclass(frozen=True)
class Problem:
    """The fit's data, sorted by star-tracker time, times from t0 (the gyro node at or before the first
    star-tracker sample); ``mounting``: mu is estimated too (P = 9 parameters instead of 6)."""

    t_g: FloatArray  # (N,) gyro times from t0
    w_R: FloatArray  # (N, 3) rates in R with the given mounting
    t_st: FloatArray  # (M,) sorted star-tracker times
    q_meas: FloatArray  # (M, 4) q_IS
    q_RS: FloatArray  # (M, 4)
    rot_RS_T: FloatArray  # (M, 3, 3) R(q_RS)^T
    weights: FloatArray  # (3,)
    scheme: int
    mounting: bool


@dataclass(frozen=True)
class Evaluation:
    """The model at x: residuals a (eq. 6), their Jacobian, Phi, the propagation, the model attitude and
    the pseudo-derivatives (empty Jacobian and psi when evaluated without derivatives)."""

    a: FloatArray  # (M, 3)
    jac: FloatArray  # (M, 3, P)
    phi: float
    prop: Propagation
    q_model: FloatArray  # (M, 4) q_IR at the samples
    psi: FloatArray  # (M, 3, P) pseudo-derivatives, R axes at t_n


def evaluate(pb: Problem, z: FloatArray, delta: FloatArray, q_mu: FloatArray, jacobian: bool = True) -> Evaluation:
    """Residuals and (with ``jacobian``) their derivatives at x = (z, Delta, mu = rotvec(q_mu)) (003 §2.2)."""
    w_rot = pb.w_R if not pb.mounting else rotations.quat_rotate(q_mu, pb.w_R)
    omega = w_rot + delta
    rate_jac = None
    if pb.mounting and jacobian:
        rate_jac = np.concatenate([np.broadcast_to(np.eye(3), (pb.t_g.size, 3, 3)), -cross_matrix(w_rot)], axis=2)
    prop = propagate(pb.t_g, omega, pb.t_st, scheme=pb.scheme, rate_jacobian=rate_jac, derivatives=jacobian)
    p0 = rotations.mrp_to_quat(z)
    q_model = rotations.quat_multiply(p0, prop.u_out)  # q_IR(t_n), |.| = |U| (scheme 1 drifts)
    r = rotations.quat_multiply(rotations.quat_conjugate(pb.q_meas), rotations.quat_multiply(q_model, pb.q_RS))
    r = np.where(r[:, :1] < 0.0, -r, r)
    a = -r[:, 1:]
    phi = float(np.sum(pb.weights * a * a))
    if not jacobian:
        empty = np.zeros((a.shape[0], 3, 0))
        return Evaluation(a=a, jac=empty, phi=phi, prop=prop, q_model=q_model, psi=empty)
    m = a.shape[0]
    # R(U)^T dPsi/dz (M, 3, 3) as one (3 M, 3) @ (3, 3) product (bit for bit the batched one, 2x faster)
    rot_t = np.ascontiguousarray(np.swapaxes(prop.rot_out, -1, -2)).reshape(3 * m, 3)
    psi_z = (rot_t @ mrp_pseudo_derivatives(z)).reshape(m, 3, 3)
    psi = np.concatenate([psi_z, prop.psi_out], axis=2)  # (M, 3, P), R axes at t_n
    psi_s = pb.rot_RS_T @ psi  # sensor axes
    # da/dx = -1/2 vec(r o psi) = -1/2 (r0 psi + r_vec x psi), the cross product written out per component
    # (the products and differences np.cross forms) and added in place (x * -0.5 is -0.5 * x bit for bit), on
    # components-first (3, P, M) copies: passes over M-long rows instead of (M, P) slices (2x faster)
    r0, r1, r2, r3 = np.ascontiguousarray(r.T)
    b0, b1, b2 = bs = np.ascontiguousarray(psi_s.transpose(1, 2, 0))
    jac_cf = r0 * bs
    jac_cf[0] += r2 * b2 - r3 * b1
    jac_cf[1] += r3 * b0 - r1 * b2
    jac_cf[2] += r1 * b1 - r2 * b0
    jac_cf *= -0.5
    jac = np.ascontiguousarray(jac_cf.transpose(2, 0, 1))
    return Evaluation(a=a, jac=jac, phi=phi, prop=prop, q_model=q_model, psi=psi)


def linear_step(ev: Evaluation, dx: FloatArray, weights: FloatArray) -> Evaluation:
    """The evaluation after a negligible step dx, to first order: a + J dx, q o (1, psi dx / 2)."""
    a = ev.a + ev.jac @ dx
    q_model = rotations.quat_multiply(ev.q_model, rotations.rotvec_to_quat(ev.psi @ dx))
    return replace(ev, a=a, phi=float(np.sum(weights * a * a)), q_model=q_model)


def normal_equations(ev: Evaluation, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """C (P, P) and d (P,) of 003 §2.2: c_kj = sum w_i da_i/dx_k da_i/dx_j, d_k = -sum w_i a_i da_i/dx_k."""
    jw = ev.jac * w[None, :, None]
    c = np.einsum("nip,niq->pq", jw, ev.jac)
    d = -np.einsum("nip,ni->p", jw, ev.a)
    return c, d


def initial_guess(pb: Problem) -> tuple[FloatArray, FloatArray]:
    """z from the first sample; Delta from the gyro-vs-tracker relative rotations of consecutive samples.

    d_n = rotvec((U_n^-1 U_{n+1})^-1 o m_n^-1 m_{n+1}) ~ int Delta dt (m_n = q_n o q_RS^-1), whose sum
    telescopes the tracker noise: Delta0 = sum d_n / (t_M - t_1).
    """
    meas = rotations.quat_multiply(pb.q_meas, rotations.quat_conjugate(pb.q_RS))  # q_IR measured
    z0 = rotations.quat_to_mrp(rotations.quat_canonical(meas[0]))
    # the attitude propagated with Delta = 0 (the residuals at z0 are not needed: propagate, not evaluate)
    prop = propagate(pb.t_g, pb.w_R + np.zeros(3), pb.t_st, scheme=pb.scheme, derivatives=False)
    u = rotations.quat_normalize(prop.u_out)
    model_rel = rotations.quat_multiply(rotations.quat_conjugate(u[:-1]), u[1:])
    meas_rel = rotations.quat_multiply(rotations.quat_conjugate(meas[:-1]), meas[1:])
    d = rotations.quat_to_rotvec(rotations.quat_multiply(rotations.quat_conjugate(model_rel), meas_rel))
    span = pb.t_st[-1] - pb.t_st[0]
    delta0 = np.sum(d, axis=0) / span if span > 0 else np.zeros(3)
    return z0, delta0


# ---------------------------------------------------------------------------------------------------
# The Gauss-Newton iteration (003 §2.2) from the first guess.


@dataclass(frozen=True)
class State:
    """An iterate x = (z, Delta[, mu = rotvec(q_mu)]) and the model evaluated there."""

    z: FloatArray
    delta: FloatArray
    q_mu: FloatArray
    ev: Evaluation


@dataclass(frozen=True)
class GaussNewton:
    """The final iterate, the number of iterations, whether it converged and why it stopped; normal_matrix: C
    (P, P) of the final iterate's Jacobian when the iteration formed it (converged or stopped), else None."""

    state: State
    iterations: int
    converged: bool
    status: str
    mounting: bool
    normal_matrix: FloatArray | None = None

    @property
    def x(self) -> FloatArray:
        """(z, Delta[, mu]) (P,)."""
        st = self.state
        return np.concatenate([st.z, st.delta] + ([rotations.quat_to_rotvec(st.q_mu)] if self.mounting else []))


def _first_order(pb: Problem, st: State, dx: FloatArray) -> State:
    """The negligible last step dx, applied to first order rather than paying for another evaluation."""
    q_mu = st.q_mu
    if pb.mounting:
        q_mu = rotations.quat_multiply(rotations.rotvec_to_quat(dx[6:9]), q_mu)
    return State(st.z + dx[:3], st.delta + dx[3:6], q_mu, linear_step(st.ev, dx, pb.weights))


def _moved(pb: Problem, st: State, dx: FloatArray, step: float) -> State:
    """The model at x + step dx, z kept on the MRP set with |z| <= 1 (the shadow set is the same rotation)."""
    z_new = st.z + step * dx[:3]
    if z_new @ z_new > 1.0:
        z_new = -z_new / (z_new @ z_new)
    delta_new = st.delta + step * dx[3:6]
    q_mu_new = st.q_mu
    if pb.mounting:
        q_mu_new = rotations.quat_multiply(rotations.rotvec_to_quat(step * dx[6:9]), st.q_mu)
    return State(z_new, delta_new, q_mu_new, evaluate(pb, z_new, delta_new, q_mu_new))


def _line_search(pb: Problem, st: State, dx: FloatArray) -> State | None:
    """The first of the steps dx, dx/2, ... (30 halvings) that does not raise Phi; None if none."""
    step = 1.0
    for _ in range(30):
        new = _moved(pb, st, dx, step)
        if new.ev.phi <= st.ev.phi * (1.0 + 1e-12) + 1e-300:
            return new
        step *= 0.5
    return None


def gauss_newton(pb: Problem, max_iterations: int, tolerance: float) -> GaussNewton:
    """Gauss-Newton: C dx = d with scaled columns until every correction is below ``tolerance`` times the
    parameter's paper sigma; a step that raises Phi is halved."""
    m, n_par = pb.t_st.size, 9 if pb.mounting else 6
    z, delta = initial_guess(pb)
    q_mu = np.array([1.0, 0.0, 0.0, 0.0])
    st = State(z, delta, q_mu, evaluate(pb, z, delta, q_mu))
    for iteration in range(1, max_iterations + 1):
        c, d = normal_equations(st.ev, pb.weights)
        c_inv, _ = scaled_inverse(c)
        dx = c_inv @ d
        sigma_w = max(np.sqrt(st.ev.phi / (3 * m - n_par)), SIGMA_FLOOR)
        if np.all(np.abs(dx) <= tolerance * sigma_w * np.sqrt(np.diag(c_inv))):
            # the first-order step keeps the Jacobian, so C is the final iterate's too
            return GaussNewton(_first_order(pb, st, dx), iteration, True, "converged", pb.mounting, c)
        new = _line_search(pb, st, dx)
        if new is None:
            return GaussNewton(st, iteration, False, "stopped: no step decreases Phi", pb.mounting, c)
        st = new
    return GaussNewton(st, max_iterations, False, f"not converged in {max_iterations} iterations", pb.mounting)
