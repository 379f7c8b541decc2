"""Definitive attitude over a whole arc (beyond papers 003 and 000): a multiplicative EKF with a
Rauch-Tung-Striebel smoother over every star-tracker head and the gyros, with augmented calibration states
(gyro scale factors, Pittelkau's misalignment/non-orthogonality, further heads' mountings, the
gyro-to-star-tracker time offset), the observability of each state from the information in the arc, and
consistency statistics (NIS, innovation whiteness).

Modules: ``model`` (state layout, gyro model, settings), ``gyro`` (rates or increments as steps, refined
onto the epochs), ``propagation`` (the vectorised block propagation between epochs), ``filter`` (forward
MEKF), ``smoother`` (RTS), ``observability``, ``estimate`` (the whole estimator), ``reference`` (a plain
per-gyro-step MEKF + RTS, the benchmark's and the tests' yardstick), ``comparison`` (gyro_bias_fit and the
000 calibration on the same data, side by side).
"""
