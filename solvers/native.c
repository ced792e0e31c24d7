/* Per-point kernels of the solvers package, compiled and loaded by solvers/native.py (geometry/native.py's
 * loader); the numpy paths compute the same operations in the same order (tests/solvers/test_native.py). */
#include <math.h>
#include <stddef.h>

/* numpy's maximum: NaN if either argument is NaN */
static double np_max(double a, double b) { return isnan(a) ? a : (isnan(b) ? b : (a > b ? a : (a < b ? b : a))); }
static double np_min(double a, double b) { return isnan(a) ? a : (isnan(b) ? b : (a < b ? a : (a > b ? b : a))); }

/* PieceProfile.h_local (solvers/timing.py): dt/dx = d / sqrt(q) at x = x0 + xl[m], q the uniform quadratic B-spline
 * of the n knot intervals' control points c (n + 2) in its basis form (bspline.value); with ``ends``, in the end
 * intervals their closed form (no bumps or rises: q12 = q1, q2 of the first, then of the last interval). */
void fs_h_local(int n, double d, const double *c, int x0, int K, const double *xl_in, int ends, const double *q12,
                double *out) {
    double root_d = 2.0 * sqrt(d);
    for (int m = 0; m < K; m++) {
        double xl = np_min(np_max(xl_in[m], -(double)x0), (double)(n - x0));
        double fl = floor(xl);
        long long k = isnan(fl) ? 0 : (long long)fl + x0;
        if (k < 0) k = 0;
        if (k > n - 1) k = n - 1;
        double t = xl - (double)(k - x0);
        double u = 1.0 - t;
        double v = 0.5 * (c[k] * u * u + c[k + 1] * (1.0 + 2.0 * t * u) + c[k + 2] * t * t);
        out[m] = d / sqrt(np_max(v, 0.0));
        if (!ends) continue;
        /* the end intervals' closed form without bumps: 2 sqrt(d) / sqrt(q1 + q2 d w^2 / 2), w from the rest end */
        double x = xl + (double)x0;
        if (x < 1.0) {
            double r = q12[0] + 0.5 * q12[1] * d * x * x;
            out[m] = root_d / sqrt(r);
        } else if (x > n - 1.0) {
            double w = (double)(n - x0) - xl;
            double r = q12[2] + 0.5 * q12[3] * d * w * w;
            out[m] = root_d / sqrt(r);
        }
    }
}

/* bspline.basis: knot interval k (clamped to [k_lo, k_hi]) and the weights W0, W1, W2 (K x 3 each, one after the
 * other in W) of c_k, c_k+1, c_k+2 in q, q' and q'' at s[m]. */
void fs_basis(int K, const double *s, double d, int k_lo, int k_hi, long long *k_out, double *W) {
    double *W0 = W, *W1 = W + 3 * (size_t)K, *W2 = W + 6 * (size_t)K;
    double w2a = 1.0 / (d * d), w2b = -2.0 / (d * d);
    for (int m = 0; m < K; m++) {
        double x = s[m] / d;
        double kf = np_min(np_max(floor(x), (double)k_lo), (double)k_hi);
        long long k = isnan(kf) ? (long long)k_lo : (long long)kf;
        double t = x - (double)k;
        double u = 1.0 - t;
        k_out[m] = k;
        W0[3 * m] = u * u / 2.0;
        W0[3 * m + 1] = ((-2.0 * t) * t + 2.0 * t + 1.0) / 2.0;
        W0[3 * m + 2] = t * t / 2.0;
        W1[3 * m] = -u / d;
        W1[3 * m + 1] = (1.0 - 2.0 * t) / d;
        W1[3 * m + 2] = t / d;
        W2[3 * m] = w2a;
        W2[3 * m + 1] = w2b;
        W2[3 * m + 2] = w2a;
    }
}

/* bspline.evaluate: q, q', q'' at s[m] of the control points c (starting at global index col0), knot intervals
 * clamped to [k_lo, hi]; q, q', q'' one after the other in out. */
void fs_evaluate(int K, const double *s, double d, int k_lo, int hi, int col0, const double *c, double *out) {
    double *q = out, *q1 = out + K, *q2 = out + 2 * (size_t)K;
    double dd = d * d;
    for (int m = 0; m < K; m++) {
        double x = s[m] / d;
        double kf = np_min(np_max(floor(x), (double)k_lo), (double)hi);
        long long k = isnan(kf) ? (long long)k_lo : (long long)kf;
        double t = x - (double)k;
        long long i = k - col0;
        double c0 = c[i], c1 = c[i + 1], c2 = c[i + 2];
        double a2 = c0 - 2.0 * c1 + c2;
        double a1 = c1 - c0;
        double u = 1.0 - t;
        q[m] = 0.5 * (c0 * u * u + c1 * (1.0 + 2.0 * t * u) + c2 * t * t);
        q1[m] = (a1 + a2 * t) / d;
        q2[m] = a2 / dd;
    }
}

/* kinematics.axis_kinematics: v = x_s sdot, a = x_ss sdot^2 + x_s sddot, j = x_sss sdot^3 + 3 x_ss sdot sddot +
 * x_s sdddot (K x 3 each, one after the other in out). */
void fs_axis_kinematics(int K, const double *sdot, const double *sddot, const double *sdddot, const double *d1,
                        const double *d2, const double *d3, double *out) {
    double *v = out, *a = out + 3 * (size_t)K, *j = out + 6 * (size_t)K;
    for (int m = 0; m < K; m++) {
        double f = sdot[m], f2 = f * f, f3 = f2 * f, g = sddot[m], h = sdddot[m], fg = 3.0 * f * g;
        for (int c = 0; c < 3; c++) {
            int i = 3 * m + c;
            v[i] = d1[i] * f;
            a[i] = d2[i] * f2 + d1[i] * g;
            j[i] = d3[i] * f3 + d2[i] * fg + d1[i] * h;
        }
    }
}

/* min over the three axes of num[c] / x where x > eps (else inf), x = X[m][c]^2 (square) or |X[m][c]| (numpy's
 * np.min(np.where(x > eps, num / x, inf), axis=1): NaN if any term is NaN). */
void fs_min_ratio(int K, const double *X, const double *num, double eps, int square, double *out) {
    for (int m = 0; m < K; m++) {
        double best = INFINITY;
        for (int c = 0; c < 3; c++) {
            double x = X[3 * m + c];
            x = square ? x * x : fabs(x);
            double r = x > eps ? num[c] / x : INFINITY;
            best = c == 0 ? r : np_min(best, r);
        }
        out[m] = best;
    }
}

/* lp.column_reach: out[j] (ncols, filled with inf by the caller) = min over points m and i = 0..2 with
 * j = k[m] + i, W0[m][i] >= min_basis (and ok[m], if ok) of cap[m] / W0[m][i].  Returns 0, or -1 if a column is
 * out of range (the caller's numpy path then). */
int fs_column_reach(int K, const long long *k, const double *W0, const double *cap, int ncols, double min_basis,
                    const unsigned char *ok, double *out) {
    for (int m = 0; m < K; m++) {
        if (ok != NULL && !ok[m]) continue;
        for (int i = 0; i < 3; i++) {
            double w = W0[3 * m + i];
            if (!(w >= min_basis)) continue;
            long long j = k[m] + i;
            if (j < 0 || j >= ncols) return -1;
            out[j] = np_min(out[j], cap[m] / w);
        }
    }
    return 0;
}
