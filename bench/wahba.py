"""Wahba benchmark (issue 8): batch QUEST and q-method on 1,000,000 epochs of two and three vectors,
against the ``ahrs`` package's QUEST looped per epoch and scipy's ``Rotation.align_vectors`` per epoch
(the peers on a subset), in the same run.

Run: ``.venv/bin/python bench/wahba.py [--epochs N] [--subset M] [--repeat K]``.
Target: at least 1,000,000 solutions/s for batch QUEST. Wall and CPU (process) times are both printed:
on a shared machine the CPU figure is the one that does not depend on the other jobs.
``ahrs`` is an optional peer (``pip install ahrs``); without it its rows are skipped with a message.
Last column: for the q-method, the median angle (rad) to the noise-free truth (the noise level); for
every other solver, the largest angle between its solutions and the q-method's on the same epochs.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from processing.attitude import rotations, wahba


def make_case(n: int, n_vec: int, noise_rad: float, seed: int = 0) -> tuple[np.ndarray, ...]:
    """Random attitudes q_BR, reference vectors r (n, n_vec, 3), observations b = R(q) r + noise, weights."""
    rng = np.random.default_rng(seed)
    q = rotations.quat_canonical(rotations.quat_normalize(rng.normal(size=(n, 4))))
    if n_vec == 2:  # the ahrs setting: gravity (0, 0, 1) and a magnetic field dipping 60 deg
        dip = np.deg2rad(60.0)
        r = np.broadcast_to(np.array([[0.0, 0.0, 1.0], [np.cos(dip), 0.0, -np.sin(dip)]]), (n, 2, 3)).copy()
    else:
        r = rng.normal(size=(n, n_vec, 3))
        r /= np.linalg.norm(r, axis=-1, keepdims=True)
    b = rotations.quat_rotate(q[:, None, :], r) + noise_rad * rng.normal(size=r.shape)
    b /= np.linalg.norm(b, axis=-1, keepdims=True)
    w = np.full(n_vec, 1.0 / n_vec)
    return q, b, r, w


def timed(fn: Callable[[], np.ndarray], repeat: int) -> tuple[float, float, np.ndarray]:
    best_wall, best_cpu, out = np.inf, np.inf, None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best_wall = min(best_wall, time.perf_counter() - w0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    assert out is not None
    return best_wall, best_cpu, out


def ahrs_quest_loop(b: np.ndarray, r: np.ndarray, w: np.ndarray) -> np.ndarray | None:
    try:
        from ahrs.filters import QUEST
    except ImportError:
        return None
    # ahrs's references: gravity (0, 0, 1) fixed, the field given as a vector (make_case's r); it returns
    # Shuster's quaternion (q4, qv) in scalar-first order, i.e. the conjugate of our Hamilton q_BR.
    assert np.allclose(r[:, 0], [0.0, 0.0, 1.0]) and np.allclose(r[:, 1], r[0, 1])
    est = QUEST(weights=np.asarray(w, dtype=float), magnetic_dip=np.asarray(r[0, 1], dtype=float))
    out = np.array([est.estimate(b[i, 0], b[i, 1]) for i in range(b.shape[0])])
    return rotations.quat_conjugate(out)


def scipy_loop(b: np.ndarray, r: np.ndarray, w: np.ndarray) -> np.ndarray:
    return np.array([Rotation.align_vectors(b[i], r[i], weights=w)[0].as_quat(scalar_first=True)
                     for i in range(b.shape[0])])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=1_000_000)
    ap.add_argument("--subset", type=int, default=5_000, help="epochs for the per-epoch peers")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--noise-rad", type=float, default=1e-3)
    args = ap.parse_args(argv)
    print(f"Wahba benchmark: {args.epochs:,} epochs (peers on {args.subset:,}), best of {args.repeat}, "
          f"noise {args.noise_rad:g} rad per axis")
    header = f"{'solver':42s} {'vectors':>7s} {'epochs':>10s} {'wall s':>8s} {'solutions/s':>13s} " \
             f"{'cpu solutions/s':>16s} {'angle rad':>14s}"
    print(header)
    print("-" * len(header))
    results: dict[tuple[str, int], float] = {}
    for n_vec in (2, 3):
        q_true, b, r, w = make_case(args.epochs, n_vec, args.noise_rad, seed=n_vec)
        batch = {
            "processing.attitude.wahba.q_method (batch, LAPACK)": lambda b=b, r=r, w=w: wahba.q_method(b, r, w,
                                                                                               covariance=False).q,
            "processing.attitude.wahba.quest (batch)": lambda b=b, r=r, w=w: wahba.quest(b, r, w, covariance=False).q,
            "processing.attitude.wahba.quest (batch, + covariance)": lambda b=b, r=r, w=w: wahba.quest(b, r, w).q,
            "processing.attitude.wahba.esoq2 (batch)": lambda b=b, r=r, w=w: wahba.esoq2(b, r, w, covariance=False).q,
        }
        ours = None
        for name, fn in batch.items():
            wall, cpu, q = timed(fn, args.repeat)
            if ours is None:  # the q-method (LAPACK eigenvectors) is the reference of the agreement column
                ours = q
                err = float(np.median(rotations.angle_between(q, q_true)))
            else:
                err = float(np.max(rotations.angle_between(q, ours)))
            results[(name, n_vec)] = args.epochs / wall
            print(f"{name:42s} {n_vec:7d} {args.epochs:10,d} {wall:8.3f} {args.epochs / wall:13,.0f} "
                  f"{args.epochs / cpu:16,.0f} {err:14.2e}")
        assert ours is not None
        m = min(args.subset, args.epochs)
        wall, cpu, q = timed(lambda b=b, r=r, w=w, m=m: scipy_loop(b[:m], r[:m], w), 1)
        diff = float(np.max(rotations.angle_between(q, ours[:m])))
        print(f"{'scipy Rotation.align_vectors (per epoch)':42s} {n_vec:7d} {m:10,d} {wall:8.3f} {m / wall:13,.0f} "
              f"{m / cpu:16,.0f} {diff:14.2e}")
        results[("scipy", n_vec)] = m / wall
        if n_vec == 2:
            w0, c0 = time.perf_counter(), time.process_time()
            q = ahrs_quest_loop(b[:m], r[:m], w)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            if q is None:
                print(f"{'ahrs QUEST (per epoch)':42s}   skipped: the ahrs package is not installed (pip install ahrs)")
            else:
                diff = float(np.max(rotations.angle_between(q, ours[:m])))
                print(f"{'ahrs.filters.QUEST.estimate (per epoch)':42s} {n_vec:7d} {m:10,d} {wall:8.3f} "
                      f"{m / wall:13,.0f} {m / cpu:16,.0f} {diff:14.2e}")
                results[("ahrs", n_vec)] = m / wall
        else:
            print(f"{'ahrs QUEST (per epoch)':42s}   n/a: ahrs's QUEST takes exactly two vectors (gravity, field)")
    quest3 = results[("processing.attitude.wahba.quest (batch)", 3)]
    print(f"\nbatch QUEST, three vectors: {quest3:,.0f} solutions/s (target 1,000,000): "
          f"{'met' if quest3 >= 1e6 else 'NOT met (wall clock; see the CPU column)'}")
    for peer in ("scipy", "ahrs"):
        for n_vec in (2, 3):
            if (peer, n_vec) in results:
                print(f"speed-up of batch QUEST over {peer} per epoch, {n_vec} vectors: "
                      f"{results[('processing.attitude.wahba.quest (batch)', n_vec)] / results[(peer, n_vec)]:,.0f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
