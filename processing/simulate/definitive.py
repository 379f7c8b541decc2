"""Truth simulator for the definitive attitude and the gyro noise: several star-tracker heads, gyro rates or
increments with a bias random walk, scale factors and misalignment, a star-tracker time-tag error, and the
noise processes of an Allan analysis.

Pure and deterministic (same arguments, same output; no I/O); one ``numpy.random.Generator`` per random
quantity from ``SeedSequence(seed).spawn``, so changing e.g. the gyro rate leaves the star-tracker noise
unchanged.

Model:

- motion: circular orbit (processing.orbits.two_body), q_IB = q_IO_003 o q_OB(t) with q_OB from a manoeuvre
  plan of processing.simulate.seed000 (``motion="agile"``: slews and scans about random axes, exact body
  rates) or held in the orbital frame (``motion="earth"``: a constant rotation about the orbit normal,
  the 003 case in which a scale factor and the bias of that axis look alike);
- gyro in the configured frame G (q_BG): w_meas = (I + K) R_BG^T w_B + b(t) + white noise of angle random
  walk ``arw`` (rad/sqrt(s)); b(t) = b0 + a random walk of sigma_u (``bias_random_walk``, rad/s/sqrt(s));
  K = diag(scale) + the six misalignments (processing.definitive.model). ``gyro="rates"``: instantaneous
  rates every ``gyro_period_s`` (noise std arw / sqrt(period)); ``gyro="increments"``: the integral over
  each period (two-point Gauss-Legendre of the exact rate, as seed000) with noise std arw sqrt(period);
- star-tracker heads: q_IS(tag) = q_IB(tag + time_offset) o q_BS,true o exp(n), n ~ N(0, diag(sigma²))
  about the sensor axes, every ``period_s`` from ``phase_s``; the configuration holds q_BS,configured
  (= true for the first head; a further head's may be off by ``mounting_error_rad``).

:func:`gyro_noise_rates` draws the rate errors of an Allan test: white (angle random walk N), flicker
(bias instability B, two-sided PSD B² / (2 pi f), Kasdin & Walter 1992 / Kasdin 1995 filter: one-sided PSD
2 Q tau0 / (2 sin(pi f tau0)) -> Q / (pi f), so Q = B²) and random walk (rate random walk K, sigma K
sqrt(tau0) per step); Allan variance N²/tau + (2 ln 2 / pi) B² + K² tau / 3 (IEEE Std 952, Annex C).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.random import PCG64, Generator, SeedSequence
from numpy.typing import NDArray

from processing.attitude import rotations
from processing.frames.orbital import q_IO_003
from processing.orbits.two_body import circular_orbit_state, mean_motion_rad_s, sun_synchronous_inclination_rad
from processing.simulate.seed000 import ManeuverPlan, plan_maneuvers
from processing.units import NS_PER_S, R_EARTH_M, RAD_PER_ARCSEC, RAD_PER_DEG

FloatArray = NDArray[np.float64]
_GL = np.array([-1.0, 1.0]) / np.sqrt(3.0)
_CHUNK = 1 << 16


class DefinitiveSimulationError(ValueError):
    """A simulator parameter outside its domain."""


@dataclass(frozen=True)
class HeadSpec:
    """One star-tracker head: name, true mounting q_BS (4,), noise sigma about x, y, z (rad), sampling
    period and phase (s), and the error of its configured mounting (rotation vector, rad: configured =
    true o exp(-error), i.e. the true mounting is the configured one turned by ``mounting_error_rad``)."""

    name: str
    q_BS: tuple[float, float, float, float]
    sigma_rad: tuple[float, float, float] = (3 * RAD_PER_ARCSEC, 3 * RAD_PER_ARCSEC, 20 * RAD_PER_ARCSEC)
    period_s: float = 1.0
    phase_s: float = 0.0
    mounting_error_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)


def default_heads(n: int = 2, sigma_rad: tuple[float, float, float] | None = None,
                  period_s: float = 1.0) -> tuple[HeadSpec, ...]:
    """One or two heads: st1 looking along body -z turned 30 deg (as 000's), st2 about 100 deg from it."""
    sig = sigma_rad or (3 * RAD_PER_ARCSEC, 3 * RAD_PER_ARCSEC, 20 * RAD_PER_ARCSEC)
    q1 = rotations.quat_from_axis_angle([1.0, 0.0, 0.0], -150.0 * RAD_PER_DEG)
    q2 = rotations.quat_multiply(rotations.quat_from_axis_angle([0.0, 0.0, 1.0], 100.0 * RAD_PER_DEG), q1)
    heads = [HeadSpec("st1", tuple(q1.tolist()), sig, period_s)]
    if n > 1:
        heads.append(HeadSpec("st2", tuple(rotations.quat_canonical(q2).tolist()), sig, period_s,
                              mounting_error_rad=(40 * RAD_PER_ARCSEC, -25 * RAD_PER_ARCSEC, 60 * RAD_PER_ARCSEC)))
    return tuple(heads)


@dataclass(frozen=True)
class TruthDefinitive:
    """Known truth: plan and orbit (q_IB(t_s), w_B(t_s) callables through :meth:`q_IB` and :meth:`w_B`),
    gyro_time_tai_ns (N,), bias_G_rad_s (N, 3) at those times, K (3, 3), q_BG, arw, bias random walk,
    heads (name -> HeadSpec), q_BS_configured (name -> (4,)), time_offset_s, per head the sample times."""

    start_tai_ns: int
    plan: ManeuverPlan
    orbit: tuple[float, float, float, float]
    gyro_time_tai_ns: NDArray[np.int64]
    bias_G_rad_s: FloatArray
    K: FloatArray
    q_BG: FloatArray
    arw_rad_sqrt_s: float
    bias_random_walk_rad_s_sqrt_s: float
    heads: dict[str, HeadSpec]
    q_BS_configured: dict[str, FloatArray]
    time_offset_s: float
    st_time_tai_ns: dict[str, NDArray[np.int64]] = field(default_factory=dict)

    def seconds(self, t_ns: Any) -> FloatArray:
        return (np.asarray(t_ns, dtype=np.int64) - np.int64(self.start_tai_ns)).astype(np.float64) / NS_PER_S

    def q_IB(self, t_s: Any) -> FloatArray:
        t = np.asarray(t_s, dtype=np.float64)
        r, v = circular_orbit_state(t, *self.orbit)
        return rotations.quat_canonical(rotations.quat_multiply(q_IO_003(r, v), self.plan.q_OB(t)))

    def w_B(self, t_s: Any) -> FloatArray:
        return self.plan.w_B(np.asarray(t_s, dtype=np.float64))

    def bias_at(self, t_ns: Any) -> FloatArray:
        """True bias (..., 3) in G, linearly interpolated between gyro samples."""
        t = self.seconds(t_ns)
        tg = self.seconds(self.gyro_time_tai_ns)
        return np.stack([np.interp(t, tg, self.bias_G_rad_s[:, i]) for i in range(3)], axis=-1)


@dataclass(frozen=True)
class ScenarioDefinitive:
    """streams {"star_tracker", "gyro" or "gyro_increments"} in the canonical schemas, the configuration
    (DESIGN.md JSON), the truth and the parameters."""

    streams: dict[str, dict[str, NDArray[Any]]]
    config: dict[str, Any]
    truth: TruthDefinitive
    parameters: dict[str, Any]


def k_matrix_from(scale: tuple[float, float, float], misalignment: tuple[float, ...]) -> FloatArray:
    """K from 3 scale factors and the 6 misalignments (K_xy, K_xz, K_yx, K_yz, K_zx, K_zy)."""
    m = misalignment
    return np.array([[scale[0], m[0], m[1]], [m[2], scale[1], m[3]], [m[4], m[5], scale[2]]], dtype=np.float64)


def _plan(motion: str, duration_s: float, n_rad_s: float, rng: Generator) -> ManeuverPlan:
    if motion == "earth":
        return plan_maneuvers(duration_s, rng, mean_motion=n_rad_s, initial_hold_s=duration_s + 1.0,
                              slew_duration_s=(40.0, 60.0), slew_peak_rate_rad_s=(0.0, 0.0),
                              scan_duration_s=(60.0, 120.0), scan_peak_rate_rad_s=(0.0, 0.0),
                              hold_duration_s=(0.0, 0.0))
    if motion == "agile":
        return plan_maneuvers(duration_s, rng, mean_motion=n_rad_s, initial_hold_s=60.0,
                              slew_duration_s=(30.0, 60.0), slew_peak_rate_rad_s=(0.5 * RAD_PER_DEG, 2 * RAD_PER_DEG),
                              scan_duration_s=(60.0, 120.0),
                              scan_peak_rate_rad_s=(0.1 * RAD_PER_DEG, 0.5 * RAD_PER_DEG),
                              hold_duration_s=(10.0, 60.0))
    raise DefinitiveSimulationError(f"motion must be 'earth' or 'agile', got {motion!r}")


def simulate_definitive(
    *,
    start_tai_ns: int,
    duration_s: float = 1800.0,
    seed: int = 0,
    motion: Literal["earth", "agile"] = "agile",
    heads: tuple[HeadSpec, ...] | None = None,
    gyro: Literal["rates", "increments"] = "rates",
    gyro_period_s: float = 0.1,
    q_BG: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    bias_rad_s: tuple[float, float, float] = (2e-5, -1.5e-5, 1e-5),
    bias_random_walk_rad_s_sqrt_s: float = 2e-9,
    arw_rad_sqrt_s: float = 0.5 * RAD_PER_ARCSEC,
    scale_factor: tuple[float, float, float] = (0.0, 0.0, 0.0),
    misalignment: tuple[float, float, float, float, float, float] = (0.0,) * 6,
    time_offset_s: float = 0.0,
    altitude_m: float = 700e3,
) -> ScenarioDefinitive:
    """Simulate star-tracker heads and a gyro with known truth (module docstring). Keyword-only; SI units."""
    parameters = dict(locals())
    if duration_s <= 0 or gyro_period_s <= 0:
        raise DefinitiveSimulationError("duration_s and gyro_period_s must be > 0")
    if gyro not in ("rates", "increments"):
        raise DefinitiveSimulationError(f"gyro must be 'rates' or 'increments', got {gyro!r}")
    heads = heads if heads is not None else default_heads(2)
    rng_plan, rng_gyro, rng_bias, *rng_st = (Generator(PCG64(s)) for s in SeedSequence(seed).spawn(3 + len(heads)))
    a = R_EARTH_M + altitude_m
    orbit = (a, float(sun_synchronous_inclination_rad(a)), 100.0 * RAD_PER_DEG, 0.0)
    plan = _plan(motion, duration_s, float(mean_motion_rad_s(a)), rng_plan)
    K = k_matrix_from(scale_factor, misalignment)
    q_BG_arr = rotations.quat_canonical(rotations.quat_normalize(np.asarray(q_BG, dtype=np.float64)))
    truth_partial = TruthDefinitive(
        start_tai_ns=int(start_tai_ns), plan=plan, orbit=orbit, gyro_time_tai_ns=np.zeros(0, dtype=np.int64),
        bias_G_rad_s=np.zeros((0, 3)), K=K, q_BG=q_BG_arr, arw_rad_sqrt_s=arw_rad_sqrt_s,
        bias_random_walk_rad_s_sqrt_s=bias_random_walk_rad_s_sqrt_s, heads={h.name: h for h in heads},
        q_BS_configured={}, time_offset_s=time_offset_s)
    g_t, g_cols, bias = _gyro_stream(truth_partial, duration_s, gyro, gyro_period_s, np.asarray(bias_rad_s),
                                     rng_gyro, rng_bias)
    st_cols, st_times, q_cfg = _star_trackers(truth_partial, heads, duration_s, rng_st)
    truth = TruthDefinitive(
        start_tai_ns=int(start_tai_ns), plan=plan, orbit=orbit, gyro_time_tai_ns=g_t, bias_G_rad_s=bias, K=K,
        q_BG=q_BG_arr, arw_rad_sqrt_s=arw_rad_sqrt_s, bias_random_walk_rad_s_sqrt_s=bias_random_walk_rad_s_sqrt_s,
        heads={h.name: h for h in heads}, q_BS_configured=q_cfg, time_offset_s=time_offset_s,
        st_time_tai_ns=st_times)
    config = {"star_trackers": {name: {"q_BS": q.tolist()} for name, q in q_cfg.items()},
              "gyro": {"q_BG": q_BG_arr.tolist()}}
    stream = "gyro" if gyro == "rates" else "gyro_increments"
    return ScenarioDefinitive(streams={"star_tracker": st_cols, stream: g_cols}, config=config, truth=truth,
                              parameters=parameters)


def _gyro_stream(tr: TruthDefinitive, duration_s: float, kind: str, period_s: float, b0: FloatArray,
                 rng: Generator, rng_bias: Generator) -> tuple[NDArray[np.int64], dict[str, NDArray[Any]],
                                                              FloatArray]:
    n = int(np.floor(duration_s / period_s + 1e-9)) + (1 if kind == "rates" else 0)
    k = np.arange(n, dtype=np.int64) + (0 if kind == "rates" else 1)
    period_ns = int(round(period_s * NS_PER_S))
    t_ns = np.int64(tr.start_tai_ns) + k * period_ns
    t_s = (k * period_ns).astype(np.float64) / NS_PER_S
    walk = np.cumsum(rng_bias.standard_normal((n, 3)) * tr.bias_random_walk_rad_s_sqrt_s * np.sqrt(period_s), axis=0)
    bias = b0 + walk
    A = (np.eye(3) + tr.K) @ rotations.quat_to_dcm(tr.q_BG).T
    out = np.empty((n, 3))
    for a in range(0, n, _CHUNK):
        ts = t_s[a:a + _CHUNK]
        if kind == "rates":
            out[a:a + _CHUNK] = tr.w_B(ts) @ A.T
        else:
            nodes = (ts - 0.5 * period_s)[:, None] + 0.5 * period_s * _GL
            w = tr.w_B(nodes)  # (n, 2, 3)
            out[a:a + _CHUNK] = (0.5 * period_s * w.sum(axis=1)) @ A.T
    noise = rng.standard_normal((n, 3)) * tr.arw_rad_sqrt_s
    if kind == "rates":
        meas = out + bias + noise / np.sqrt(period_s)
        cols = {c: meas[:, i].copy() for i, c in enumerate(("wx", "wy", "wz"))}
    else:
        meas = out + bias * period_s + noise * np.sqrt(period_s)  # bias at the end of the interval: O(rw) error
        cols = {**{c: meas[:, i].copy() for i, c in enumerate(("dax", "day", "daz"))},
                "interval_s": np.full(n, period_s)}
    cols = {"time_tai_ns": t_ns, **cols, "sensor": np.full(n, "gyro", dtype=object)}
    return t_ns, cols, bias


def _star_trackers(tr: TruthDefinitive, heads: tuple[HeadSpec, ...], duration_s: float, rngs: list[Generator]
                   ) -> tuple[dict[str, NDArray[Any]], dict[str, NDArray[np.int64]], dict[str, FloatArray]]:
    cols: dict[str, list[NDArray[Any]]] = {k: [] for k in ("time_tai_ns", "q0", "q1", "q2", "q3", "sensor")}
    times: dict[str, NDArray[np.int64]] = {}
    q_cfg: dict[str, FloatArray] = {}
    for h, rng in zip(heads, rngs, strict=True):
        n = int(np.floor((duration_s - h.phase_s) / h.period_s + 1e-9)) + 1
        t_ns = np.int64(tr.start_tai_ns) + np.round((h.phase_s + np.arange(n) * h.period_s) * NS_PER_S).astype(np.int64)
        t_true = tr.seconds(t_ns) + tr.time_offset_s
        q_BS = rotations.quat_canonical(rotations.quat_normalize(np.asarray(h.q_BS, dtype=np.float64)))
        noise = rng.standard_normal((n, 3)) * np.asarray(h.sigma_rad)
        q_IS = rotations.quat_multiply(rotations.quat_multiply(tr.q_IB(t_true), q_BS), rotations.rotvec_to_quat(noise))
        q_IS = rotations.quat_canonical(q_IS)
        times[h.name] = t_ns
        q_cfg[h.name] = rotations.quat_canonical(rotations.quat_multiply(
            q_BS, rotations.rotvec_to_quat(-np.asarray(h.mounting_error_rad, dtype=np.float64))))
        cols["time_tai_ns"].append(t_ns)
        for i in range(4):
            cols[f"q{i}"].append(q_IS[:, i])
        cols["sensor"].append(np.full(n, h.name, dtype=object))
    return {k: np.concatenate(v) for k, v in cols.items()}, times, q_cfg


def gyro_noise_rates(n: int, period_s: float, *, arw_rad_sqrt_s: float = 0.0, bias_instability_rad_s: float = 0.0,
                     rate_random_walk_rad_s_sqrt_s: float = 0.0, seed: int = 0, axes: int = 3) -> FloatArray:
    """Gyro rate errors (n, axes) rad/s every period_s: white + flicker + random walk (module docstring)."""
    if n < 2 or period_s <= 0:
        raise DefinitiveSimulationError("need n >= 2 samples and period_s > 0")
    g_w, g_f, g_r = (Generator(PCG64(s)) for s in SeedSequence(seed).spawn(3))
    out = g_w.standard_normal((n, axes)) * (arw_rad_sqrt_s / np.sqrt(period_s))
    if bias_instability_rad_s > 0:
        out += flicker_noise(n, axes, g_f) * bias_instability_rad_s
    if rate_random_walk_rad_s_sqrt_s > 0:
        out += np.cumsum(g_r.standard_normal((n, axes)) * rate_random_walk_rad_s_sqrt_s * np.sqrt(period_s), axis=0)
    return out


def flicker_noise(n: int, axes: int, rng: Generator) -> FloatArray:
    """Unit flicker (1/f) noise (n, axes) by the Kasdin & Walter filter (alpha = 1, Q = 1): one-sided PSD
    2 tau0 / (2 sin(pi f tau0)) ~ 1 / (pi f); filter h_0 = 1, h_k = h_{k-1} (k - 1 + alpha/2) / k applied by
    FFT convolution."""
    k = np.arange(1, n)
    h = np.concatenate([[1.0], np.cumprod((k - 0.5) / k)])
    w = rng.standard_normal((n, axes))
    size = 1 << int(np.ceil(np.log2(2 * n)))
    y = np.fft.irfft(np.fft.rfft(h, size)[:, None] * np.fft.rfft(w, size, axis=0), size, axis=0)[:n]
    return y
