"""Times the sequence of examples/ekf_timing.rs with filterpy's ExtendedKalmanFilter.

Same state (pose + n beacons on a ring of radius 5 m), same models (midpoint velocity motion,
range-bearing observation with a wrapped bearing residual), same noise. filterpy propagates
the full covariance densely (F P F^T over the whole state) and uses the Joseph form, so its
cost is O(n^3) per step; that is what the comparison shows. Prints `filterpy <beacons> <ns>`.
"""
import math
import sys
import time

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter


class SlamEkf(ExtendedKalmanFilter):
    """EKF whose prediction applies the velocity model to the pose part of x."""

    def __init__(self, dim_x):
        super().__init__(dim_x=dim_x, dim_z=2)
        self.u = (0.0, 0.0, 0.1)

    def predict_x(self, u=0):
        v, w, dt = self.u
        th = self.x[2, 0]
        phi = th + w * dt / 2.0
        self.x[0, 0] += v * dt * math.cos(phi)
        self.x[1, 0] += v * dt * math.sin(phi)
        self.x[2, 0] = wrap(th + w * dt)


def wrap(a):
    a = math.fmod(a + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi


def run(n, iters):
    dim = 3 + 2 * n
    ekf = SlamEkf(dim)
    ekf.x = np.zeros((dim, 1))
    ring = [i / n * 2.0 * math.pi for i in range(n)]
    for i, a in enumerate(ring):
        ekf.x[3 + 2 * i, 0] = 5.0 * math.cos(a)
        ekf.x[4 + 2 * i, 0] = 5.0 * math.sin(a)
    ekf.P = np.eye(dim) * 1e-4
    ekf.P[3:, 3:] = np.eye(2 * n) * 0.01
    sv, sw = 0.0119, 0.0012
    ekf.R = np.diag([0.1 ** 2, 0.05 ** 2])

    def hx(x, j):
        dx = x[3 + 2 * j, 0] - x[0, 0]
        dy = x[4 + 2 * j, 0] - x[1, 0]
        return np.array([[math.hypot(dx, dy)], [wrap(math.atan2(dy, dx) - x[2, 0])]])

    def hjac(x, j):
        dx = x[3 + 2 * j, 0] - x[0, 0]
        dy = x[4 + 2 * j, 0] - x[1, 0]
        q = dx * dx + dy * dy
        d = math.sqrt(q)
        h = np.zeros((2, dim))
        h[0, 0:3] = [-dx / d, -dy / d, 0.0]
        h[1, 0:3] = [dy / q, -dx / q, -1.0]
        h[0, 3 + 2 * j:5 + 2 * j] = [dx / d, dy / d]
        h[1, 3 + 2 * j:5 + 2 * j] = [-dy / q, dx / q]
        return h

    def residual(a, b):
        r = a - b
        r[1, 0] = wrap(r[1, 0])
        return r

    start = time.perf_counter()
    for k in range(iters):
        v, w, dt = ekf.u
        phi = ekf.x[2, 0] + w * dt / 2.0
        F = np.eye(dim)
        F[0, 2] = -v * dt * math.sin(phi)
        F[1, 2] = v * dt * math.cos(phi)
        L = np.zeros((dim, 2))
        L[0, :] = [dt * math.cos(phi), -v * dt * dt / 2 * math.sin(phi)]
        L[1, :] = [dt * math.sin(phi), v * dt * dt / 2 * math.cos(phi)]
        L[2, :] = [0.0, dt]
        ekf.F = F
        ekf.Q = L @ np.diag([sv * sv, sw * sw]) @ L.T
        ekf.predict()
        j = k % n
        z = np.array([[5.0], [ring[j]]])
        ekf.update(z, lambda x: hjac(x, j), lambda x: hx(x, j), residual=residual)
    return (time.perf_counter() - start) / iters * 1e9


if __name__ == "__main__":
    for n, iters in [(4, 5000), (50, 1000), (200, 100)]:
        print(f"filterpy {n} {run(n, iters):.0f}")
        sys.stdout.flush()
