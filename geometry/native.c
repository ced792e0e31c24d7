/* Per-point kernels of the geometry package: NURBS evaluation (C(u) and its u-derivatives), the map to
 * arc-length derivatives, and the inverse guesses of a monotone table (geometry/quadrature.py).
 *
 * Compiled and loaded by geometry/native.py; the numpy paths in geometry/nurbs.py, geometry/toolpath.py and
 * geometry/quadrature.py compute the same formulas (tests/geometry/test_native.py compares them).
 *
 * fs_nurbs_taylor, fs_nurbs_eval: the homogeneous B-spline A(u) = sum_i N_{i,p}(u) [w_i P_i, w_i] as a Taylor
 * polynomial about each knot span's midpoint, its coefficients from de Boor's basis function derivatives
 * (Piegl & Tiller, The NURBS Book, algorithm A2.3) there; per point Horner for A and three derivatives (de Boor's
 * basis functions at the point itself on a span's start and at the domain's end), then the quotient rule
 * (eq. 4.8):
 *
 *     C   = A / W
 *     C'   = (A'   - W' C) / W
 *     C''  = (A''  - 2 W' C'  - W'' C) / W
 *     C''' = (A''' - 3 W' C'' - 3 W'' C' - W''' C) / W
 *
 * The knot span of u is the one with U[i] <= u < U[i+1] (right-continuous at interior knots, as
 * scipy.interpolate.BSpline), and the last non-empty span for u at the domain's end U[n].
 *
 * fs_arc_ders: u-derivatives C', C'', C''' to arc-length derivatives C_s, C_ss, C_sss with
 * g = |C'|^2, u_s = g^-1/2, u_ss = -(C'.C'') u_s^4, u_sss = (4 (C'.C'')^2 u_s^2 - |C''|^2 - C'.C''') u_s^5.
 */
#include <stdlib.h>
#include <math.h>

/* numpy's maximum and minimum: NaN if either argument is NaN */
static double np_max(double a, double b) { return isnan(a) ? a : (isnan(b) ? b : (a > b ? a : (a < b ? b : a))); }
static double np_min(double a, double b) { return isnan(a) ? a : (isnan(b) ? b : (a < b ? a : (a > b ? b : a))); }
/* numpy's clip(x, lo, hi) = minimum(maximum(x, lo), hi) */
static double np_clip(double x, double lo, double hi) { return np_min(np_max(x, lo), hi); }

/* Basis functions N_{i-p..i,p} and their derivatives up to order nd (<= p) at u, ders[k*(p+1)+j]
 * (A2.3). Work arrays: ndu (p+1)^2, a 2(p+1), left and right p+1 each. */
static void ders_basis(int i, double u, int p, int nd, const double *U, double *ders, double *ndu,
                       double *a, double *left, double *right) {
    int P = p + 1;
    ndu[0] = 1.0;
    for (int j = 1; j <= p; j++) {
        left[j] = u - U[i + 1 - j];
        right[j] = U[i + j] - u;
        double saved = 0.0;
        for (int r = 0; r < j; r++) {
            ndu[j * P + r] = right[r + 1] + left[j - r];            /* lower triangle: knot differences */
            double temp = ndu[r * P + j - 1] / ndu[j * P + r];
            ndu[r * P + j] = saved + right[r + 1] * temp;           /* upper triangle: basis functions */
            saved = left[j - r] * temp;
        }
        ndu[j * P + j] = saved;
    }
    for (int j = 0; j <= p; j++) ders[j] = ndu[j * P + p];
    for (int r = 0; r <= p; r++) {
        double *as1 = a, *as2 = a + P;
        as1[0] = 1.0;
        for (int k = 1; k <= nd; k++) {
            double d = 0.0;
            int rk = r - k, pk = p - k;
            if (r >= k) {
                as2[0] = as1[0] / ndu[(pk + 1) * P + rk];
                d = as2[0] * ndu[rk * P + pk];
            }
            int j1 = rk >= -1 ? 1 : -rk;
            int j2 = (r - 1 <= pk) ? k - 1 : p - r;
            for (int j = j1; j <= j2; j++) {
                as2[j] = (as1[j] - as1[j - 1]) / ndu[(pk + 1) * P + rk + j];
                d += as2[j] * ndu[(rk + j) * P + pk];
            }
            if (r <= pk) {
                as2[k] = -as1[k - 1] / ndu[(pk + 1) * P + r];
                d += as2[k] * ndu[r * P + pk];
            }
            ders[k * P + r] = d;
            double *t = as1; as1 = as2; as2 = t;
        }
    }
    double f = p;
    for (int k = 1; k <= nd; k++) {
        for (int j = 0; j <= p; j++) ders[k * P + j] *= f;
        f *= (p - k);
    }
}

/* The homogeneous B-spline's derivatives up to nd at u in span i, A[k][c] = A_c^(k)(u) (zero above nd). */
static void hom_ders(int i, double u, int p, int nd, const double *U, const double *Pw, double *work,
                     double A[][4]) {
    int P = p + 1;
    double *ndu = work, *a = ndu + P * P, *left = a + 2 * P, *right = left + P, *ders = right + P;
    ders_basis(i, u, p, nd, U, ders, ndu, a, left, right);
    for (int k = 0; k <= nd; k++) {
        double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
        for (int r = 0; r <= p; r++) {
            const double *pw = Pw + 4 * (i - p + r);
            double b = ders[k * P + r];
            s0 += b * pw[0];
            s1 += b * pw[1];
            s2 += b * pw[2];
            s3 += b * pw[3];
        }
        A[k][0] = s0; A[k][1] = s1; A[k][2] = s2; A[k][3] = s3;
    }
}

/* doubles of work space for hom_ders at degree p */
static size_t work_size(int p) { return (size_t)(p + 1) * (size_t)(2 * (p + 1) + 4 + 2 + 2 + 1); }

/* Taylor coefficients of the homogeneous B-spline about the midpoint of each span: for span j (U index
 * span[j], U[span[j]] < U[span[j] + 1]), coef[(j*(p+1) + k)*4 + c] = A_c^(k)(mid[j]) / k!.  Returns 0, or -1
 * without memory. */
int fs_nurbs_taylor(int p, int n, const double *U, const double *Pw, int m, const int *span, const double *mid,
                    double *coef) {
    int P = p + 1;
    double *work = malloc(sizeof(double) * work_size(p));
    double (*A)[4] = malloc(sizeof(double[4]) * (size_t)P);
    if (!work || !A) { free(work); free(A); return -1; }
    for (int j = 0; j < m; j++) {
        hom_ders(span[j], mid[j], p, p, U, Pw, work, A);
        double fact = 1.0;
        for (int k = 0; k <= p; k++) {
            if (k > 0) fact *= k;
            double *cf = coef + ((size_t)j * P + k) * 4;
            for (int c = 0; c < 4; c++) cf[c] = A[k][c] / fact;
        }
    }
    free(work);
    free(A);
    return 0;
}

/* C and its u-derivatives up to order (<= 3) at u[0..K-1]: out[(k*K + q)*3 + c].  From the Taylor coefficients of
 * fs_nurbs_taylor (m spans starting at lo[j], U index span[j], about mid[j]), but for a point on a span's start
 * or at the domain's end U[n] (and beyond), where the homogeneous spline comes from de Boor's basis functions
 * at the point itself: the clamped ends give their control points exactly, as they did before the
 * expansions.  A point is in the last span whose start is at or below it (the first span for points below
 * it).  With exact0, A itself (not its derivatives) comes from de Boor's basis functions at every point, the
 * numpy path's value: Horner's rounding follows its largest partial sums, which near a long span's ends
 * outgrow the control points (bench seed 5029's last segment: 1.4e-14 mm against de Boor's 9e-15 mm, and
 * 4x that in the second differences of samples near its end).  Returns 0, or -1 without memory. */
int fs_nurbs_eval(int p, int n, const double *U, const double *Pw, int m, const int *span, const double *lo,
                  const double *mid, const double *coef, int K, const double *u, int order, int exact0, double *out) {
    int P = p + 1;
    int nd = order < p ? order : p;
    double *work = malloc(sizeof(double) * work_size(p));
    if (!work) return -1;
    double end = U[n];
    int j = 0;
    for (int q = 0; q < K; q++) {
        double uq = u[q];
        if (!(j < m && lo[j] <= uq && (j + 1 == m || uq < lo[j + 1]))) { /* (sorted u: mostly the same span) */
            int a = 0, b = m; /* largest a with lo[a] <= uq, or 0 */
            while (b - a > 1) {
                int c = (a + b) / 2;
                if (uq < lo[c]) b = c; else a = c;
            }
            j = a;
        }
        double A[4][4] = {{0.0}};
        if (uq == lo[j] || uq >= end) {
            hom_ders(span[j], uq >= end ? end : uq, p, nd, U, Pw, work, A);
        } else {
            double t = uq - mid[j];
            const double *cf = coef + (size_t)j * P * 4;
            for (int c = 0; c < 4; c++) {
                double v = cf[p * 4 + c], d1 = 0.0, d2 = 0.0, d3 = 0.0;
                for (int k = p - 1; k >= 0; k--) {
                    d3 = d3 * t + 3.0 * d2;
                    d2 = d2 * t + 2.0 * d1;
                    d1 = d1 * t + v;
                    v = v * t + cf[k * 4 + c];
                }
                A[0][c] = v; A[1][c] = d1; A[2][c] = d2; A[3][c] = d3;
            }
            if (exact0) { /* A itself by de Boor at u, as the numpy path (exact points) */
                double B[1][4];
                hom_ders(span[j], uq, p, 0, U, Pw, work, B);
                for (int c = 0; c < 4; c++) A[0][c] = B[0][c];
            }
        }
        double W0 = A[0][3], W1 = A[1][3], W2 = A[2][3], W3 = A[3][3];
        for (int c = 0; c < 3; c++) {
            double C0 = A[0][c] / W0;
            out[(size_t)q * 3 + c] = C0;
            if (order < 1) continue;
            double C1 = (A[1][c] - W1 * C0) / W0;
            out[((size_t)K + q) * 3 + c] = C1;
            if (order < 2) continue;
            double C2 = (A[2][c] - 2.0 * W1 * C1 - W2 * C0) / W0;
            out[(2 * (size_t)K + q) * 3 + c] = C2;
            if (order < 3) continue;
            out[(3 * (size_t)K + q) * 3 + c] = (A[3][c] - 3.0 * W1 * C2 - 3.0 * W2 * C1 - W3 * C0) / W0;
        }
    }
    free(work);
    return 0;
}

/* D[(k*K + m)*3 + c] (k = 0..3) to C_s, C_ss, C_sss (K x 3 each, one after the other in out). */
void fs_arc_ders(int K, const double *D, double *out) {
    double *d1 = out, *d2 = out + 3 * (size_t)K, *d3 = out + 6 * (size_t)K;
    const double *C1 = D + 3 * (size_t)K, *C2 = D + 6 * (size_t)K, *C3 = D + 9 * (size_t)K;
    for (int m = 0; m < K; m++) {
        const double *a = C1 + 3 * (size_t)m, *b = C2 + 3 * (size_t)m, *c = C3 + 3 * (size_t)m;
        double g = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
        double g12 = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        double g22 = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
        double g13 = a[0] * c[0] + a[1] * c[1] + a[2] * c[2];
        double us = 1.0 / sqrt(g);
        double us2 = us * us;
        double us4 = us2 * us2;
        double uss = -g12 * us4;
        double usss = (4.0 * g12 * g12 * us2 - (g22 + g13)) * (us4 * us);
        double us3 = us2 * us, t2 = 3.0 * us * uss;
        for (int k = 0; k < 3; k++) {
            d1[3 * (size_t)m + k] = a[k] * us;
            d2[3 * (size_t)m + k] = b[k] * us2 + a[k] * uss;
            d3[3 * (size_t)m + k] = c[k] * us3 + b[k] * t2 + a[k] * usss;
        }
    }
}

/* MonotoneTable.inverse's guesses (geometry/quadrature.py), the same operations in the same order as its numpy
 * code, point by point: x with F(x) = y[q] for K values y.  Breakpoints x_b, F_b (nb), f at them from inside the
 * interval on its right (fa) and left (fz); with fp (f' at the breakpoints, or NULL) and quintic flags (nb - 1),
 * the quintic guess in flagged intervals.  out[q] = the guess, j[q] = its interval, and newton[q] = 1 where the
 * cubic guess was taken and a Newton step is to follow (``step``: 0 without one). */
void fs_table_guess(int nb, const double *x_b, const double *F_b, const double *fa, const double *fz,
                    const double *fp, const unsigned char *quintic, int step, int K, const double *y_in,
                    double *out, long long *j_out, unsigned char *newton) {
    double total = F_b[nb - 1];
    int j = 0;
    for (int q = 0; q < K; q++) {
        double y = np_clip(y_in[q], 0.0, total);
        /* searchsorted(F_b, y, 'right') - 1 (the last breakpoint at or below y), clipped to [0, nb - 2]; sorted y
         * mostly stay in the previous point's interval or move to the next one */
        if (j + 1 < nb && F_b[j] <= y && y < F_b[j + 1]) {
        } else if (j + 2 < nb && F_b[j + 1] <= y && y < F_b[j + 2]) {
            j++;
        } else {
            int a = 0, b = nb; /* first index with F_b[i] > y is in [a, b] */
            while (a < b) {
                int c = (a + b) / 2;
                if (F_b[c] <= y) a = c + 1; else b = c;
            }
            j = a - 1;
        }
        if (j < 0) j = 0;
        if (j > nb - 2) j = nb - 2;
        double x0 = x_b[j], x1 = x_b[j + 1];
        double h = F_b[j + 1] - F_b[j];
        double x;
        int use_quintic = step && quintic != NULL && quintic[j];
        if (use_quintic) {
            double f0 = fa[j], f1 = fz[j + 1];
            double t = (y - F_b[j]) / h;
            double m0 = h / f0, m1 = h / f1;
            double c0 = -h * h * fp[j] / pow(f0, 3.0), c1 = -h * h * fp[j + 1] / pow(f1, 3.0);
            double t2 = t * t;
            double t3 = t2 * t;
            double b0 = 1.0 - t3 * (10.0 - t * (15.0 - 6.0 * t));
            double b5 = 1.0 - b0;
            double b1 = t * (1.0 - t2 * (6.0 - t * (8.0 - 3.0 * t)));
            double u = 1.0 - t;
            double b2 = 0.5 * t2 * pow(u, 3.0);
            double b3 = 0.5 * t3 * (u * u);
            double b4 = -t3 * (4.0 - t * (7.0 - 3.0 * t));
            x = b0 * x0 + b1 * m0 + b2 * c0 + b3 * c1 + b4 * m1 + b5 * x1;
        } else {
            double t = h > 0.0 ? (y - F_b[j]) / h : 0.0;
            double w = 3.0 * (x1 - x0);
            double m0 = np_min(h / np_max(fa[j], 1e-300), w);
            double m1 = np_min(h / np_max(fz[j + 1], 1e-300), w);
            double t2 = t * t, t3 = t * t * t;
            x = (2.0 * t3 - 3.0 * t2 + 1.0) * x0 + (t3 - 2.0 * t2 + t) * m0 + (-2.0 * t3 + 3.0 * t2) * x1
                + (t3 - t2) * m1;
        }
        out[q] = np_clip(x, x0, x1);
        j_out[q] = j;
        newton[q] = (unsigned char)(step && !use_quintic);
    }
}
