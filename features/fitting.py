"""Circle and line fits to a segment's points (paper section 2.2), as numba kernels.

Circle fits, all returning (x0, y0, r, ok):
- `fit_circle_paper`: the paper's modified Gauss-Newton (Levenberg-Marquardt) on eq. (6),
  E = sum [(x - x0)^2 + (y - y0)^2 - r^2]^2, with lambda0 = 0.01, x10 on a failed step, /10 on
  a successful one, stopping when the relative change of E is below `tol` or after `max_iter`
  steps. It starts from the circle through the first three points (paper) and falls back to the
  Kasa fit when those are nearly collinear. Note (docs/method.md section 4): eq. (6) *is*
  Kasa's algebraic objective, so this converges to the Kasa solution and shares its bias toward
  small circles on short arcs.
- `fit_circle_kasa`: Kasa's algebraic fit in closed form (linear least squares).
- `fit_circle_taubin`: Taubin's algebraic fit (Chernov's recommended initial guess), for context.
- `fit_circle_geometric`: orthogonal-distance Levenberg-Marquardt on sum (|p - c| - r)^2,
  started from Taubin's fit; `circle_covariance` gives the 3x3 covariance of (x0, y0, r).

`fit_line_tls`: total least squares line with (alpha, rho) covariance and projected endpoints.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "DAMPING_STEPS",
    "fit_circle_paper",
    "fit_circle_kasa",
    "fit_circle_taubin",
    "fit_circle_geometric",
    "circle_covariance",
    "circle_ssr",
    "fit_line_tls",
]


# The damping loops of the two Levenberg-Marquardt fits raise lambda x10 per rejected step until
# it reaches 1e12. From the least positive double (5e-324) that takes 336 steps, so a positive
# lambda always ends the loop by its own test first; the cap ends it when lambda has underflowed
# to 0 (a tiny lambda0 divided by 10 on each accepted step), where x10 would never get there,
# or is negative. A fit thus ends after at most max_iter steps of at most DAMPING_STEPS tries.
DAMPING_STEPS = 336


@njit(cache=True, nogil=True, error_model="numpy")
def _solve_sym3(A, b):
    """Solve a symmetric positive definite 3x3 system A x = b by Cholesky, without allocating.

    A: its upper triangle (a00, a01, a02, a11, a12, a22); b: (b0, b1, b2) (tuples of floats).
    Returns (x0, x1, x2, ok); ok=False when the matrix is not (numerically) positive definite.
    """
    a00, a01, a02, a11, a12, a22 = A
    b0, b1, b2 = b
    eps = 1e-13 * max(abs(a00), abs(a11), abs(a22))
    if not (a00 > eps):
        return 0.0, 0.0, 0.0, False
    l00 = math.sqrt(a00)
    l10 = a01 / l00
    l20 = a02 / l00
    d1 = a11 - l10 * l10
    if not (d1 > eps):
        return 0.0, 0.0, 0.0, False
    l11 = math.sqrt(d1)
    l21 = (a12 - l20 * l10) / l11
    d2 = a22 - l20 * l20 - l21 * l21
    if not (d2 > eps):
        return 0.0, 0.0, 0.0, False
    l22 = math.sqrt(d2)
    y0 = b0 / l00
    y1 = (b1 - l10 * y0) / l11
    y2 = (b2 - l20 * y0 - l21 * y1) / l22
    x2 = y2 / l22
    x1 = (y1 - l21 * x2) / l11
    x0 = (y0 - l10 * x1 - l20 * x2) / l00
    return x0, x1, x2, True


@njit(cache=True, nogil=True, error_model="numpy")
def _centred_moments(x, y):
    """Mean point and the moments of the centred points u, v (z = u^2 + v^2), averaged:
    (mx, my, Mxx, Myy, Mxy, Mxz, Myz, Mzz). Both algebraic fits start from these."""
    n = x.shape[0]
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += x[i]
        my += y[i]
    mx /= n
    my /= n
    Mxx = 0.0
    Myy = 0.0
    Mxy = 0.0
    Mxz = 0.0
    Myz = 0.0
    Mzz = 0.0
    for i in range(n):
        u = x[i] - mx
        v = y[i] - my
        z = u * u + v * v
        Mxx += u * u
        Myy += v * v
        Mxy += u * v
        Mxz += u * z
        Myz += v * z
        Mzz += z * z
    return mx, my, Mxx / n, Myy / n, Mxy / n, Mxz / n, Myz / n, Mzz / n


@njit(cache=True, nogil=True, error_model="numpy")
def fit_circle_kasa(x, y):
    """Kasa: minimise sum (x^2 + y^2 + B x + C y + D)^2, linear in (B, C, D).

    In centred coordinates (where the sums of u and v vanish) the normal equations are
    [[Mxx, Mxy, 0], [Mxy, Myy, 0], [0, 0, 1]] [B, C, D] = -[Mxz, Myz, Mz].
    """
    if x.shape[0] < 3:
        return 0.0, 0.0, 0.0, False
    mx, my, Mxx, Myy, Mxy, Mxz, Myz, _ = _centred_moments(x, y)
    B, C, D, ok = _solve_sym3((Mxx, Mxy, 0.0, Myy, 0.0, 1.0), (-Mxz, -Myz, -(Mxx + Myy)))
    if not ok:
        return 0.0, 0.0, 0.0, False
    uc = -0.5 * B
    vc = -0.5 * C
    r2 = uc * uc + vc * vc - D
    if not (r2 > 0.0) or not math.isfinite(r2):
        return 0.0, 0.0, 0.0, False
    return uc + mx, vc + my, math.sqrt(r2), True


@njit(cache=True, nogil=True, error_model="numpy")
def fit_circle_taubin(x, y):
    """Taubin's algebraic fit (Newton on the characteristic polynomial, as in Chernov's code)."""
    if x.shape[0] < 3:
        return 0.0, 0.0, 0.0, False
    mx, my, Mxx, Myy, Mxy, Mxz, Myz, Mzz = _centred_moments(x, y)
    Mz = Mxx + Myy
    Cov_xy = Mxx * Myy - Mxy * Mxy
    Var_z = Mzz - Mz * Mz
    if not (Mz > 0.0):
        return 0.0, 0.0, 0.0, False
    A3 = 4.0 * Mz
    A2 = -3.0 * Mz * Mz - Mzz
    A1 = Var_z * Mz + 4.0 * Cov_xy * Mz - Mxz * Mxz - Myz * Myz
    A0 = Mxz * (Mxz * Myy - Myz * Mxy) + Myz * (Myz * Mxx - Mxz * Mxy) - Var_z * Cov_xy
    A22 = A2 + A2
    A33 = A3 + A3 + A3
    xn = 0.0
    yn = 1e20
    for _ in range(99):
        yold = yn
        yn = A0 + xn * (A1 + xn * (A2 + xn * A3))
        if abs(yn) > abs(yold):
            xn = 0.0
            break
        dy = A1 + xn * (A22 + xn * A33)
        if dy == 0.0:
            break
        xold = xn
        xn = xold - yn / dy
        if abs((xn - xold) / xn if xn != 0.0 else 1.0) < 1e-12:
            break
        if xn < 0.0:
            xn = 0.0
            break
    det = xn * xn - xn * Mz + Cov_xy
    if det == 0.0 or not math.isfinite(det):
        return 0.0, 0.0, 0.0, False
    uc = (Mxz * (Myy - xn) - Myz * Mxy) / det / 2.0
    vc = (Myz * (Mxx - xn) - Mxz * Mxy) / det / 2.0
    r2 = uc * uc + vc * vc + Mz
    if not (r2 > 0.0) or not math.isfinite(uc + vc):
        return 0.0, 0.0, 0.0, False
    return uc + mx, vc + my, math.sqrt(r2), True


@njit(cache=True, nogil=True, error_model="numpy")
def _circle_through3(x, y):
    """Circumcircle of the first three points; ok=False when they are (nearly) collinear."""
    x1, x2, x3 = x[0], x[1], x[2]
    y1, y2, y3 = y[0], y[1], y[2]
    ax = x2 - x1
    ay = y2 - y1
    bx = x3 - x1
    by = y3 - y1
    d = 2.0 * (ax * by - ay * bx)
    la = ax * ax + ay * ay
    lb = bx * bx + by * by
    # |d|/2 = |a||b| sin(angle at p1): collinear when the sine is below 1e-3
    if abs(d) <= 2e-3 * math.sqrt(la * lb) or la == 0.0 or lb == 0.0:
        return 0.0, 0.0, 0.0, False
    ux = (by * la - ay * lb) / d
    uy = (ax * lb - bx * la) / d
    return x1 + ux, y1 + uy, math.sqrt(ux * ux + uy * uy), True


@njit(cache=True, nogil=True, error_model="numpy")
def _kasa_energy(x, y, x0, y0, r):
    e = 0.0
    for i in range(x.shape[0]):
        dx = x[i] - x0
        dy = y[i] - y0
        g = dx * dx + dy * dy - r * r  # eq. (7)
        e += g * g  # eq. (6)
    return e


@njit(cache=True, nogil=True, error_model="numpy")
def fit_circle_paper(x, y, lambda0=0.01, max_iter=100, tol=1e-10, max_init_radius=1e3):
    """The paper's modified Gauss-Newton on eq. (6); returns (x0, y0, r, ok, n_iter)."""
    n = x.shape[0]
    if n < 3:
        return 0.0, 0.0, 0.0, False, 0
    x0, y0, r, ok = _circle_through3(x, y)
    if not ok or r > max_init_radius:
        x0, y0, r, ok = fit_circle_kasa(x, y)  # fallback: nearly collinear first three points
        if not ok:
            return 0.0, 0.0, 0.0, False, 0
    lam = lambda0
    E = _kasa_energy(x, y, x0, y0, r)
    it = 0
    while it < max_iter:
        it += 1
        h00 = h01 = h02 = h11 = h12 = h22 = 0.0  # A^T A (upper triangle)
        g0 = g1 = g2 = 0.0  # -A^T g
        for i in range(n):
            dx = x[i] - x0
            dy = y[i] - y0
            g = dx * dx + dy * dy - r * r  # eq. (7)
            a0 = -2.0 * dx  # eq. (8): dg/dx0, dg/dy0, dg/dr
            a1 = -2.0 * dy
            a2 = -2.0 * r
            h00 += a0 * a0
            h01 += a0 * a1
            h02 += a0 * a2
            h11 += a1 * a1
            h12 += a1 * a2
            h22 += a2 * a2
            g0 -= a0 * g
            g1 -= a1 * g
            g2 -= a2 * g
        improved = False
        dE = 0.0
        tries = 0
        while lam < 1e12 and tries < DAMPING_STEPS:
            tries += 1
            # eq. (9): (A^T A + lambda I) dp = -A^T g
            s0, s1, s2, okk = _solve_sym3(
                (h00 + lam, h01, h02, h11 + lam, h12, h22 + lam), (g0, g1, g2)
            )
            if not okk:
                lam *= 10.0
                continue
            E_new = _kasa_energy(x, y, x0 + s0, y0 + s1, r + s2)  # Step 2
            if E_new < E:  # Step 4: accept, decrease lambda
                lam /= 10.0
                x0 += s0
                y0 += s1
                r += s2
                improved = True
                dE = E - E_new
                E = E_new
                break
            lam *= 10.0  # Step 3: reject, increase lambda
        if not improved or dE <= tol * max(E, 1e-300):
            break
    r = abs(r)
    if not (math.isfinite(x0) and math.isfinite(y0) and math.isfinite(r)) or r == 0.0:
        return 0.0, 0.0, 0.0, False, it
    return x0, y0, r, True, it


@njit(cache=True, nogil=True, error_model="numpy")
def circle_ssr(x, y, x0, y0, r):
    """Sum of squared orthogonal distances of the points to the circle."""
    s = 0.0
    for i in range(x.shape[0]):
        d = math.sqrt((x[i] - x0) ** 2 + (y[i] - y0) ** 2) - r
        s += d * d
    return s


@njit(cache=True, nogil=True, error_model="numpy")
def fit_circle_geometric(x, y, max_iter=50, tol=1e-12):
    """Orthogonal-distance LM from Taubin's fit (Kasa if Taubin fails).

    Returns (x0, y0, r, ok, n_iter).
    """
    n = x.shape[0]
    if n < 3:
        return 0.0, 0.0, 0.0, False, 0
    x0, y0, r, ok = fit_circle_taubin(x, y)
    if not ok:
        x0, y0, r, ok = fit_circle_kasa(x, y)
        if not ok:
            return 0.0, 0.0, 0.0, False, 0
    E = circle_ssr(x, y, x0, y0, r)
    lam = 1e-3
    it = 0
    while it < max_iter:
        it += 1
        h00 = h01 = h02 = h11 = h12 = h22 = 0.0  # A^T A (upper triangle)
        g0 = g1 = g2 = 0.0  # -A^T g
        for i in range(n):
            dx = x[i] - x0
            dy = y[i] - y0
            d = math.sqrt(dx * dx + dy * dy)
            if d == 0.0:
                continue
            e = d - r
            j0 = -dx / d  # de/dx0, de/dy0; de/dr = -1
            j1 = -dy / d
            h00 += j0 * j0
            h01 += j0 * j1
            h02 -= j0
            h11 += j1 * j1
            h12 -= j1
            h22 += 1.0
            g0 -= j0 * e
            g1 -= j1 * e
            g2 += e
        improved = False
        dE = 0.0
        tries = 0
        while lam < 1e12 and tries < DAMPING_STEPS:  # lam >= 1e-12: 25 steps at most
            tries += 1
            f = 1.0 + lam
            s0, s1, s2, okk = _solve_sym3((h00 * f, h01, h02, h11 * f, h12, h22 * f), (g0, g1, g2))
            if not okk:
                lam *= 10.0
                continue
            E_new = circle_ssr(x, y, x0 + s0, y0 + s1, r + s2)
            if E_new <= E:
                x0 += s0
                y0 += s1
                r += s2
                dE = E - E_new
                E = E_new
                lam = max(lam / 10.0, 1e-12)
                improved = True
                break
            lam *= 10.0
        if not improved or dE <= tol * max(E, 1e-300):
            break
    if not (math.isfinite(x0) and math.isfinite(y0) and math.isfinite(r)) or r <= 0.0:
        return 0.0, 0.0, 0.0, False, it
    return x0, y0, r, True, it


@njit(cache=True, nogil=True, error_model="numpy")
def circle_covariance(x, y, x0, y0, r, sigma2):
    """(3, 3) first-order covariance of an orthogonal-distance fit (x0, y0, r) when the points are
    laser returns seen from the origin with range noise of variance sigma2.

    A range error e along beam u moves point i off the circle by e cos(inc_i), with
    cos(inc_i) = u_i . n_i (n_i the circle's normal there), so the orthogonal residuals have
    variances sigma2 cos^2(inc_i) and the fit's covariance is the sandwich
    sigma2 (J^T J)^-1 (J^T W J) (J^T J)^-1, W = diag(cos^2 inc_i), J the orthogonal-distance
    Jacobian. (Assuming isotropic point noise instead, sigma2 (J^T J)^-1, overstates the
    variance about twice on the short arcs a laser sees.) Returns (cov, ok).
    """
    h00 = h01 = h02 = h11 = h12 = h22 = 0.0
    m00 = 0.0
    m01 = 0.0
    m02 = 0.0
    m11 = 0.0
    m12 = 0.0
    m22 = 0.0
    for i in range(x.shape[0]):
        dx = x[i] - x0
        dy = y[i] - y0
        d = math.sqrt(dx * dx + dy * dy)
        rng = math.sqrt(x[i] * x[i] + y[i] * y[i])
        if d == 0.0 or rng == 0.0:
            continue
        j0 = -dx / d
        j1 = -dy / d
        cos_inc = (x[i] * dx + y[i] * dy) / (rng * d)
        w = cos_inc * cos_inc
        h00 += j0 * j0
        h01 += j0 * j1
        h02 -= j0
        h11 += j1 * j1
        h12 -= j1
        h22 += 1.0
        m00 += w * j0 * j0
        m01 += w * j0 * j1
        m02 -= w * j0
        m11 += w * j1 * j1
        m12 -= w * j1
        m22 += w
    # A = (J^T J)^-1 column by column, then cov = sigma2 A M A
    A = np.empty((3, 3))
    for c in range(3):
        e_c = (1.0 if c == 0 else 0.0, 1.0 if c == 1 else 0.0, 1.0 if c == 2 else 0.0)
        c0, c1, c2, ok = _solve_sym3((h00, h01, h02, h11, h12, h22), e_c)
        if not ok:
            return np.full((3, 3), np.nan), False
        A[0, c] = c0
        A[1, c] = c1
        A[2, c] = c2
    M = np.array([[m00, m01, m02], [m01, m11, m12], [m02, m12, m22]])
    cov = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for k in range(3):
                for j in range(3):
                    acc += A[a, k] * M[k, j] * A[j, b]
            cov[a, b] = sigma2 * acc
    for a in range(3):
        for b in range(a + 1, 3):
            m = 0.5 * (cov[a, b] + cov[b, a])
            cov[a, b] = m
            cov[b, a] = m
    return cov, True


@njit(cache=True, nogil=True, error_model="numpy")
def fit_line_tls(x, y, sigma2):
    """Total least squares line x cos(a) + y sin(a) = rho.

    Returns (alpha, rho, cov (2, 2) of (alpha, rho), endpoints (2, 2), ssr, ok).
    """
    n = x.shape[0]
    end = np.full((2, 2), np.nan)
    cov = np.full((2, 2), np.nan)
    if n < 2:
        return 0.0, 0.0, cov, end, 0.0, False
    mx, my, sxx, syy, sxy, _, _, _ = _centred_moments(x, y)
    # direction of the normal: minimiser of the scatter along it
    alpha = 0.5 * math.atan2(-2.0 * sxy, syy - sxx)
    ca = math.cos(alpha)
    sa = math.sin(alpha)
    rho = mx * ca + my * sa
    if rho < 0.0:
        rho = -rho
        alpha = alpha + math.pi if alpha <= 0.0 else alpha - math.pi
        ca = -ca
        sa = -sa
    ssr = 0.0
    stt = 0.0
    for i in range(n):
        u = x[i] - mx
        v = y[i] - my
        e = u * ca + v * sa
        t = -u * sa + v * ca
        ssr += e * e
        stt += t * t
    if stt == 0.0:
        return 0.0, 0.0, cov, end, 0.0, False
    tc = -mx * sa + my * ca  # tangential coordinate of the centroid
    var_a = sigma2 / stt
    cov[0, 0] = var_a
    cov[0, 1] = tc * var_a
    cov[1, 0] = tc * var_a
    cov[1, 1] = sigma2 / n + tc * tc * var_a
    for k in range(2):
        i = 0 if k == 0 else n - 1
        e = x[i] * ca + y[i] * sa - rho
        end[k, 0] = x[i] - e * ca
        end[k, 1] = y[i] - e * sa
    return alpha, rho, cov, end, ssr, True
